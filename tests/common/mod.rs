//! Helpers shared by the integration tests: Gmsh's Python API as an independent checker of
//! our files (`tests/external/gmsh_probe.py`).
#![allow(dead_code)] // each test binary uses a subset

use serde_json::Value;
use std::path::Path;
use std::process::Command;

/// True when Python's `gmsh` module imports. Without it a CI run fails; elsewhere the caller
/// skips visibly, and `skipped` says what did not run.
pub fn have_gmsh(skipped: &str) -> bool {
    let ok = Command::new("python3")
        .args(["-c", "import gmsh"])
        .status()
        .is_ok_and(|s| s.success());
    if !ok {
        assert!(
            std::env::var("CI").is_err(),
            "CI must have the Python gmsh module"
        );
        eprintln!("SKIPPED: Python module gmsh not available; {skipped}");
    }
    ok
}

/// Run `cmd` and insist that it succeeds (its stderr is the failure message).
pub fn run_ok(cmd: &mut Command) -> std::process::Output {
    let out = cmd.output().unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    out
}

/// Run Gmsh's own reader and Jacobians on a batch of files (the jobs are written to
/// `jobs_file`); `None` (a visible skip) when the Python module is missing outside CI.
pub fn gmsh_probe(jobs: &[Value], jobs_file: &Path) -> Option<Vec<Value>> {
    if !have_gmsh("Gmsh's Jacobian check did not run") {
        return None;
    }
    std::fs::write(jobs_file, serde_json::json!({ "jobs": jobs }).to_string()).unwrap();
    let out = run_ok(
        Command::new("python3")
            .arg(concat!(
                env!("CARGO_MANIFEST_DIR"),
                "/tests/external/gmsh_probe.py"
            ))
            .arg(jobs_file),
    );
    Some(serde_json::from_slice(&out.stdout).unwrap())
}

/// Gmsh's (min, max) det J over the elements of the written `file`, and whether they are
/// hexahedra; `None` as in [`gmsh_probe`].
pub fn gmsh_det_range(file: &Path, jobs_file: &Path) -> Option<(f64, f64, bool)> {
    let v = gmsh_probe(
        &[serde_json::json!({ "file": file, "probes": [] })],
        jobs_file,
    )?;
    let three_d = v[0]["type_name"].as_str().unwrap().contains("Hexahedron");
    Some((
        v[0]["min_det_jac"].as_f64().unwrap(),
        v[0]["max_det_jac"].as_f64().unwrap(),
        three_d,
    ))
}
