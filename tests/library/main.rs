//! Tests of the library's public API: topology, the spline space, the fit, the energy, the
//! node orderings against Gmsh's and VTK's tables, the shipped meshes' documented counts, and
//! the floors of its modules (no import cycle, no import up a floor).
//! One test binary; `cargo test --release --test library spline::` runs one module.

#[path = "../common/mod.rs"]
mod common;

mod energy;
mod fit;
mod floors;
mod generated_meshes;
mod node_ordering;
mod periodic_io;
mod real_meshes;
mod spline;
mod topology;
