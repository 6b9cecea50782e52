//! The `curve --report` JSON against its documented contract, `docs/curve-report.schema.json`,
//! with the `jsonschema` package as the oracle (`tests/external/report_schema.py`): reports of
//! a 2D and a 3D real mesh, a generated rotation sector, the elastic method, the kink smoothing at C⁰ facets, the energy fit with the global line search and
//! (with an adapter) the GPU backend validate, and every object of the schema is closed and
//! met in one of them, so a report field added without documenting it fails here.

use crate::common::{self, python, python_has, scratch_in};
use std::path::{Path, PathBuf};

const ROOT: &str = env!("CARGO_MANIFEST_DIR");

/// `curve INPUT ARGS --report` into the scratch folder: the report's path, or the failing
/// run's stderr.
fn report_of(name: &str, input: &str, args: &[&str]) -> Result<PathBuf, String> {
    let out = scratch_in("report_schema", &format!("{name}.msh"));
    let (run, report) = common::curve_with_report(&Path::new(ROOT).join(input), &out, args);
    report.ok_or_else(|| String::from_utf8_lossy(&run.stderr).into_owned())
}

#[test]
fn curve_reports_validate_against_the_documented_schema() {
    let test = common::current_test();
    if !python_has("jsonschema", &test) {
        return;
    }
    let (d2, d3) = (
        "meshes/real/dealii/example.msh",
        "meshes/real/mfem/cylinder-hex.mesh",
    );
    let sector = scratch_in("report_schema", "sector_in.msh");
    common::run_ok(
        common::polyspline()
            .args([
                "generate", "sector", "--sector", "30", "--around", "4", "--across", "4", "-o",
            ])
            .arg(&sector),
    );
    let sector = sector.to_str().unwrap().to_string();
    let mut reports = vec![
        report_of("quads", d2, &[]).unwrap(),
        report_of("hexes", d3, &[]).unwrap(),
        report_of("elastic", d2, &["--method", "elastic"]).unwrap(),
        report_of(
            "periodic",
            "meshes/real/su2-testcases/mesh_vki_turbine_prepbc.su2",
            &["--periodic", "periodic_1:periodic_2"],
        )
        .unwrap(),
        // A rotation sector: its fit is coupled across the seam (`coupled_fit_device`).
        report_of("sector", &sector, &[]).unwrap(),
        // The kinks at C⁰ facets lowered after the fit (`facet_jumps`; off by default).
        report_of("facet_jumps", d2, &["--facet-smoothing", "0.015"]).unwrap(),
        report_of(
            "energy",
            d2,
            &["--fit", "energy", "--line-search", "global"],
        )
        .unwrap(),
    ];
    // The per-rank objects are written only under mpirun (the distributed test binary).
    let mut may_miss = vec!["rank"];
    match report_of("gpu", d3, &["--backend", "gpu"]) {
        Ok(r) => {
            reports.push(r);
            // The sector's coupled fit on the device (`coupled_fit_device`: `gpu`).
            reports.push(report_of("sector_gpu", &sector, &["--backend", "gpu"]).unwrap());
        }
        Err(e) if e.contains("no GPU adapter") || e.contains("no hardware GPU adapter") => {
            common::skip(
                &test,
                &format!("the GPU report was not checked: {}", e.trim()),
            );
            may_miss.extend(["adapter", "gpu_traffic"]);
        }
        Err(e) => panic!("curve --backend gpu: {e}"),
    }
    let mut check = python();
    check
        .arg(Path::new(ROOT).join("tests/external/report_schema.py"))
        .arg(Path::new(ROOT).join("docs/curve-report.schema.json"));
    for m in may_miss {
        check.args(["--may-miss", m]);
    }
    let out = check.args(&reports).output().unwrap();
    assert!(
        out.status.success(),
        "the reports do not match docs/curve-report.schema.json:\n{}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
}
