//! The meshes: the raw result of a reader, the linear mesh and its topology, sharp features,
//! the high-order mesh, and the generated meshes.

pub mod features;
pub mod generate;
pub mod high_order;
pub mod linear;
pub mod manifold;
pub mod periodic;
pub mod raw;
pub mod topology;

pub use high_order::HighOrderMesh;
pub use linear::{InvalidElement, InvalidKind, LinearMesh, MeshOptions};
pub use topology::Topology;
