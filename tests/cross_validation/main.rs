//! The GPU kernels cross-validated against their CPU twins and analytic oracles (lavapipe is
//! enough), and naga validation of every shader. One test binary; `cargo test --release --test
//! cross_validation gpu::` runs one module.

#[path = "../common/mod.rs"]
mod common;

mod executors;
mod gpu;
