//! Kinks at C⁰ facets lowered after the fit (`fit::jumps`, `--facet-smoothing 0.015`), measured by
//! Gmsh's Jacobians of the written files alone (`tests/external/facet_angles.py`): on a ball
//! of unstructured hexes (half its elements Q2, the other half spline elements) the mean
//! facet angle drops below 0.7× the straight-sided elevation's, with no element more held
//! back than without the smoothing and the cells' Jacobian ratios kept.

use crate::common;

use serde_json::Value;
use std::path::{Path, PathBuf};

fn scratch(name: &str) -> PathBuf {
    common::scratch_in("facet_jumps", name)
}

fn curve_to(input: &Path, name: &str, extra: &[&str]) -> (PathBuf, Value) {
    let (out, report) = (
        scratch(&format!("{name}.msh")),
        scratch(&format!("{name}.json")),
    );
    common::run_ok(
        common::polyspline()
            .arg("curve")
            .arg(input)
            .arg("-o")
            .arg(&out)
            .arg("--report")
            .arg(&report)
            .args(extra),
    );
    let r = serde_json::from_slice(&std::fs::read(&report).unwrap()).unwrap();
    (out, r)
}

#[test]
fn ball_kinks_drop_below_the_straight_elevations_bound() {
    let input = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("meshes/real/dealii/unstructured_refined_ball.msh");
    let runs = [
        curve_to(&input, "ball_smoothed", &["--facet-smoothing", "0.015"]),
        curve_to(&input, "ball_off", &[]),
        curve_to(&input, "ball_straight", &["--straight"]),
    ];
    // The smoothing ran and moved points; off (the default), it did not run.
    let jumps = &runs[0].1["facet_jumps"];
    assert!(jumps["moved"].as_u64().unwrap() > 0, "{jumps}");
    assert!(
        jumps["rms_after"].as_f64().unwrap() < jumps["rms_before"].as_f64().unwrap(),
        "{jumps}"
    );
    assert!(runs[1].1["facet_jumps"].is_null());
    let held = |i: usize| runs[i].1["reduced_elements"].as_u64().unwrap();
    assert!(
        held(0) <= held(1),
        "held back {} against {} without",
        held(0),
        held(1)
    );
    if !common::have_gmsh("facet jumps") {
        return;
    }
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/external/facet_angles.py");
    let out = common::run_ok(common::python().arg(script).args(runs.iter().map(|r| &r.0)));
    let m: Vec<Value> = serde_json::from_slice(&out.stdout).unwrap();
    let f = |i: usize, k: &str| m[i][k].as_f64().unwrap();
    for (i, n) in ["smoothed", "off", "straight"].iter().enumerate() {
        eprintln!(
            "{n}: facet angle mean {:.3} p99 {:.2} max {:.2}; Jacobian ratio min {:.3} p1 {:.3}; held back {}",
            f(i, "angle_mean"),
            f(i, "angle_p99"),
            f(i, "angle_max"),
            f(i, "ratio_min"),
            f(i, "ratio_p1"),
            runs[i].1["reduced_elements"]
        );
    }
    // Half the elements are spline elements: the bound is 0.7× the straight elevation's
    // mean (without the smoothing the fit leaves 0.74×).
    let elements = runs[0].1["elements"].as_f64().unwrap();
    let q2 = runs[0].1["q2_elements"].as_f64().unwrap_or(0.0);
    eprintln!("{q2} Q2 of {elements}");
    assert!(
        f(0, "angle_mean") <= 0.7 * f(2, "angle_mean"),
        "mean facet angle {:.3}° against the straight {:.3}°",
        f(0, "angle_mean"),
        f(2, "angle_mean")
    );
    assert!(f(0, "angle_mean") < f(1, "angle_mean"));
    assert!(f(0, "angle_max") <= f(2, "angle_max") + 2.0);
    assert!(f(0, "angle_p99") <= f(2, "angle_p99") + 1.0);
    // Cells kept: Gmsh's Jacobian ratio against the straight elevation's.
    assert!(f(0, "ratio_min") >= 0.85 * f(2, "ratio_min"));
    assert!(f(0, "ratio_p1") >= 0.85 * f(2, "ratio_p1"));
    let msj = |i: usize| runs[i].1["min_scaled_jacobian"].as_f64().unwrap();
    assert!(
        msj(0) >= msj(1).min(runs[0].1["input_min_scaled_jacobian"].as_f64().unwrap()),
        "min scaled Jacobian {} against {} without",
        msj(0),
        msj(1)
    );
}
