//! Boundary fidelity on coarse smooth 3D shapes against Gmsh with the exact CAD: the O-grid
//! torus of `scripts/fidelity_shapes.py` at level 1 (192 hexes, eight cells and 45° around
//! the tube, sixteen and 22.5° around the axis), curved by the `polyspline` binary at orders 2
//! and 3 with the default options and measured by the same script (RMS and max distance of a
//! dense lattice on every boundary side from the exact torus), against Gmsh's own order-2
//! mesh of the same linear mesh with its nodes on the CAD.
//!
//! * ours is within 2.5× Gmsh-with-CAD, RMS and max, at both orders (the smooth targets of
//!   the chords' 45° turns come from circular arcs on the vertex normals; the height functions
//!   and quadrics left 14×);
//! * no crease is taken for one on the coarse torus: the default run and
//!   `--feature-angle 180` write the same mesh.
//!
//! Skipped visibly without Gmsh's Python module (a failure under `CI=true`).

use crate::common;

use serde_json::Value;
use std::path::{Path, PathBuf};
use std::process::Command;

fn dir() -> PathBuf {
    let d = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join("fidelity_3d");
    std::fs::create_dir_all(&d).unwrap();
    d
}

const SCRIPT: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/scripts/fidelity_shapes.py");

/// The linear mesh and Gmsh's CAD order-2 mesh of `shape` at `level`.
fn make(shape: &str, level: usize) -> (PathBuf, PathBuf) {
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

/// (RMS, max) distance of each file's boundary from the exact `shape`.
fn measure(shape: &str, files: &[&Path]) -> Vec<(f64, f64)> {
    let out = common::run_ok(
        common::python()
            .arg(SCRIPT)
            .args(["measure", shape, "--only", "all"])
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

fn curve(input: &Path, output: &Path, args: &[&str]) {
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

/// The coarse torus within 2.5× Gmsh-with-CAD (RMS and max) at orders 2 and 3, and curved
/// alike with and without the angle-based crease detection.
#[test]
fn coarse_torus_within_two_and_a_half_times_gmsh_with_cad() {
    if !common::have_gmsh("coarse_torus_within_two_and_a_half_times_gmsh_with_cad") {
        return;
    }
    let (linear, cad) = make("torus", 1);
    let mut files = vec![cad.clone()];
    for order in ["2", "3"] {
        let out = dir().join(format!("torus_1_o{order}.msh"));
        curve(&linear, &out, &["--order", order]);
        files.push(out);
    }
    let refs: Vec<&Path> = files.iter().map(|p| p.as_path()).collect();
    let m = measure("torus", &refs);
    let (gmsh, ours) = (m[0], &m[1..]);
    for (order, (rms, max)) in [2, 3].iter().zip(ours) {
        println!(
            "torus level 1 order {order}: RMS {rms:.3e} ({:.2}× Gmsh-with-CAD {:.3e}), max {max:.3e} ({:.2}× {:.3e})",
            rms / gmsh.0,
            gmsh.0,
            max / gmsh.1,
            gmsh.1
        );
        assert!(
            *rms <= 2.5 * gmsh.0 && *max <= 2.5 * gmsh.1,
            "torus level 1 order {order}: RMS {rms:.3e}, max {max:.3e} vs Gmsh {:.3e}, {:.3e}",
            gmsh.0,
            gmsh.1
        );
    }
    let no_angle = dir().join("torus_1_o2_no_angle.msh");
    curve(
        &linear,
        &no_angle,
        &["--order", "2", "--feature-angle", "180"],
    );
    assert_eq!(
        std::fs::read(&files[1]).unwrap(),
        std::fs::read(&no_angle).unwrap(),
        "the coarse torus is curved differently with crease detection by angle"
    );
}
