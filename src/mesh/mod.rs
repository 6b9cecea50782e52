//! Linear meshes and their topology.

pub mod features;
pub mod generate;
pub mod linear;
pub mod manifold;
pub mod topology;

pub use linear::{InvalidElement, InvalidKind, LinearMesh, MeshOptions};
pub use topology::Topology;
