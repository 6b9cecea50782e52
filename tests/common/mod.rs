//! Helpers shared by the integration tests: the Python that runs the independent checkers
//! (Gmsh's Python API, VTK, solvers' readers under `tests/external/`), and visible skips.
//!
//! Python: `$POLYSPLINE_PYTHON` if set, else the test environment `.venv-tests` that
//! `scripts/test.sh` makes, else `python3`. A check whose tool is missing fails under `CI=true`;
//! elsewhere it is skipped, and the skip is printed and appended to `$POLYSPLINE_SKIP_LOG`
//! (default `target/test-skips.log`), which `scripts/test.sh` prints at the end of the run.
#![allow(dead_code)] // each test binary uses a subset

use serde_json::Value;
use std::path::{Path, PathBuf};
use std::process::Command;

/// The Python interpreter of the checkers (see the module docs).
pub fn python_path() -> PathBuf {
    if let Some(p) = std::env::var_os("POLYSPLINE_PYTHON").filter(|p| !p.is_empty()) {
        return PathBuf::from(p);
    }
    let venv = Path::new(env!("CARGO_MANIFEST_DIR")).join(".venv-tests/bin/python");
    if venv.exists() {
        venv
    } else {
        PathBuf::from("python3")
    }
}

/// A command running the checkers' Python.
pub fn python() -> Command {
    Command::new(python_path())
}

/// Where skips are recorded.
fn skip_log() -> PathBuf {
    match std::env::var_os("POLYSPLINE_SKIP_LOG").filter(|p| !p.is_empty()) {
        Some(p) => PathBuf::from(p),
        None => Path::new(env!("CARGO_TARGET_TMPDIR"))
            .parent()
            .unwrap_or(Path::new("."))
            .join("test-skips.log"),
    }
}

/// The running test's name (the harness names each test's thread after it).
pub fn current_test() -> String {
    std::thread::current()
        .name()
        .unwrap_or("a test")
        .to_string()
}

/// True under `CI=true`, where a missing checker is a failure.
pub fn in_ci() -> bool {
    std::env::var("CI").is_ok_and(|v| v == "true" || v == "1")
}

/// Record a skipped check: panics under CI, else prints `SKIPPED: <test>: <why>` (on stdout and
/// stderr, which the harness may capture) and appends it to the skip log.
pub fn skip(test: &str, why: &str) {
    assert!(!in_ci(), "CI=true but {test} cannot run: {why}");
    let line = format!("SKIPPED: {test}: {why}");
    println!("{line}");
    eprintln!("{line}");
    use std::io::Write;
    let log = skip_log();
    if let Some(dir) = log.parent() {
        let _ = std::fs::create_dir_all(dir);
    }
    if let Ok(mut f) = std::fs::OpenOptions::new()
        .create(true)
        .append(true)
        .open(&log)
    {
        let _ = writeln!(f, "{line}");
    }
}

/// True when the checkers' Python imports `module`; otherwise a recorded skip of `test` (a
/// failure under CI).
pub fn python_has(module: &str, test: &str) -> bool {
    let ok = python()
        .args(["-c", &format!("import {module}")])
        .output()
        .is_ok_and(|o| o.status.success());
    if !ok {
        skip(
            test,
            &format!(
                "Python module {module} not importable by {} (run scripts/test.sh to install the checkers)",
                python_path().display()
            ),
        );
    }
    ok
}

/// True when Python's `gmsh` module imports. Without it a CI run fails; elsewhere the caller
/// skips visibly, and `skipped` says what did not run.
pub fn have_gmsh(skipped: &str) -> bool {
    python_has("gmsh", skipped)
}

/// `tests/external/gmsh_parts.py` with `args` (Gmsh's partitioner, its MSH 4.1 converter and
/// its reader of partitioned files; see the script), run to success: its output. Needs Gmsh's
/// Python module ([`have_gmsh`]).
pub fn gmsh_parts<S: AsRef<std::ffi::OsStr>>(
    args: impl IntoIterator<Item = S>,
) -> std::process::Output {
    run_ok(
        python()
            .arg(concat!(
                env!("CARGO_MANIFEST_DIR"),
                "/tests/external/gmsh_parts.py"
            ))
            .args(args),
    )
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
        python()
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

/// `target/tmp/<dir>/<name>`, the directory created: where a test module writes its files.
pub fn scratch_in(dir: &str, name: &str) -> PathBuf {
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join(dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir.join(name)
}

/// `target/tmp/<binary>/<test>/`, created: the calling test's own directory, so tests that
/// run in parallel never share (or race on) a file. `<test>` is the harness's name of the
/// running test (module path included), so call it from the test's own thread.
pub fn test_dir() -> PathBuf {
    let name = current_test().replace("::", "__");
    let binary = std::env::current_exe()
        .ok()
        .and_then(|p| p.file_stem().map(|s| s.to_string_lossy().into_owned()))
        .map(|s| s.split('-').next().unwrap_or("tests").to_string())
        .unwrap_or_else(|| "tests".to_string());
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR"))
        .join(binary)
        .join(name);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// Every bundled real mesh polyspline reads (`meshes/real/<source>/<file>`), sorted.
pub fn real_meshes() -> Vec<PathBuf> {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("meshes/real");
    let mut out = Vec::new();
    for d in std::fs::read_dir(root).unwrap() {
        let d = d.unwrap().path();
        if d.is_dir() {
            for f in std::fs::read_dir(d).unwrap() {
                let f = f.unwrap().path();
                out.push(f);
            }
        }
    }
    out.sort();
    out
}

/// The `polyspline` binary of this build.
pub fn polyspline() -> Command {
    Command::new(env!("CARGO_BIN_EXE_polyspline"))
}

/// `polyspline curve INPUT -o OUT --report R ARGS…` with `R` = `OUT` with the extension
/// `json` (the old `OUT` and `R` removed first): the command's output, and the report's path
/// when the command succeeded.
pub fn curve_with_report(
    input: &Path,
    out: &Path,
    args: &[&str],
) -> (std::process::Output, Option<PathBuf>) {
    let report = out.with_extension("json");
    let _ = std::fs::remove_file(out);
    let _ = std::fs::remove_file(&report);
    let run = polyspline()
        .arg("curve")
        .arg(input)
        .arg("-o")
        .arg(out)
        .arg("--report")
        .arg(&report)
        .args(args)
        .output()
        .unwrap();
    let ok = run.status.success();
    (run, ok.then_some(report))
}

/// `mesh` written as it is (order 1) to `path`, in the format of its extension.
pub fn write_linear(mesh: &polyspline::mesh::LinearMesh, path: &Path) {
    let topo = polyspline::mesh::Topology::build(mesh);
    let linear = polyspline::sample::sample(mesh, mesh, &topo, 1);
    polyspline::pipeline::write_high_order(&linear, path, &Default::default(), &[]).unwrap();
}

/// Largest coordinate difference between matching points of `a` and `b` (node lists of two
/// runs on the same mesh).
pub fn max_coordinate_gap(a: &[[f64; 3]], b: &[[f64; 3]]) -> f64 {
    a.iter()
        .zip(b)
        .map(|(p, q)| (0..3).map(|k| (p[k] - q[k]).abs()).fold(0.0, f64::max))
        .fold(0.0, f64::max)
}

/// Euclidean distance.
pub fn dist(a: [f64; 3], b: [f64; 3]) -> f64 {
    (0..3).map(|k| (a[k] - b[k]).powi(2)).sum::<f64>().sqrt()
}

/// The rows of a `compare --json` result, each asserted to have run (no `error`) and to have
/// written no invalid element: `compare` never loses a method on a valid input.
pub fn compare_rows_all_valid(compare_json: &Value) -> &[Value] {
    let rows = compare_json["rows"].as_array().expect("compare rows");
    for row in rows {
        assert!(
            row["error"].is_null(),
            "{}: {}",
            row["method"],
            row["error"]
        );
        assert_eq!(row["invalid_elements"], 0, "{}", row["method"]);
    }
    rows
}

/// What `tests/external/periodic_probe.py` finds in `file`: Gmsh's periodic links and the facet
/// angles across the seams and inside, from the written file's Jacobians.
pub fn periodic_probe(file: &Path) -> Value {
    let out = run_ok(
        python()
            .arg(concat!(
                env!("CARGO_MANIFEST_DIR"),
                "/tests/external/periodic_probe.py"
            ))
            .arg(file),
    );
    serde_json::from_slice(&out.stdout).unwrap()
}

/// The seams of `file` no rougher than its interior ([`periodic_probe`]): some seam facet
/// found, and the largest and the mean facet angle across the seams at most the interior's
/// (floored at 1e-3°, so the comparison stays meaningful where the interior is C¹ throughout).
pub fn assert_seams_no_rougher(file: &Path, what: &str) {
    let p = periodic_probe(file);
    assert!(p["seam_facets"].as_u64().unwrap() > 0, "{what}: {p}");
    for w in ["max", "mean"] {
        let seam = p[format!("seam_angle_{w}")].as_f64().unwrap();
        let inside = p[format!("interior_angle_{w}")].as_f64().unwrap();
        assert!(
            seam <= inside.max(1e-3),
            "{what}: {w} seam angle {seam}° > interior {inside}°"
        );
    }
}

/// The seams of `file` C¹ as its interior ([`periodic_probe`]): at least `facets` seam facets,
/// and the largest facet angle across the seams and inside at most 1e-4° (rounding).
pub fn assert_seams_c1(file: &Path, facets: u64, what: &str) {
    let p = periodic_probe(file);
    assert!(p["seam_facets"].as_u64().unwrap() >= facets, "{what}: {p}");
    let seam = p["seam_angle_max"].as_f64().unwrap();
    let inside = p["interior_angle_max"].as_f64().unwrap();
    assert!(
        seam <= 1e-4 && inside <= 1e-4,
        "{what}: seam {seam}°, interior {inside}°"
    );
}
