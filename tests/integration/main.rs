//! End-to-end tests, mostly through the `polyspline` binary: `curve` on every real mesh,
//! bad input and hardening (one bounded error line, no panic, no partial output), the readers'
//! mutation fuzzer, `generate`, high-order output read back by Gmsh and VTK, the elastic method,
//! boundary layers, graded knot intervals, kinks at C⁰ facets by Gmsh's Jacobians, the validity check against closed-form Jacobians, and
//! the `--report` JSON against its schema. One test binary;
//! `cargo test --release --test integration curve::` runs one module.

#[path = "../common/mod.rs"]
mod common;

mod bad_input;
mod boundary_layer;
mod curve;
mod elastic;
mod facet_jumps;
mod formats;
mod fuzz;
mod generate;
mod hardening;
mod high_order;
mod jacobian_oracle;
mod knot_intervals;
mod periodic;
mod report_schema;
