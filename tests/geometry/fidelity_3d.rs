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

// The shapes, the curving and the measure are `fidelity`'s (same script, same directory).
use super::fidelity::{curve, dir, make, measure};
use crate::common;
use std::path::Path;

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
    let m = measure("torus", &refs, "all");
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
