//! Accuracy against analytic geometry: boundary convergence of the fit modes on discs, balls
//! and tori, fidelity against Gmsh with CAD (the coarse torus in `fidelity_3d`), and feature
//! preservation (planes, rims, creases).
//! One test binary; `cargo test --release --test geometry convergence::` runs one module.

#[path = "../common/mod.rs"]
mod common;

mod convergence;
mod features;
mod fidelity;
mod fidelity_3d;
