//! polyspline: curved high-order quad/hex meshes from linear ones, without CAD.
//!
//! The pipeline (stages and seams: `docs/architecture.md`):
//!
//! ```text
//! read ──▶ LinearMesh ──▶ Topology ──▶ SplineSpace ──▶ Fit ──▶ Validity ──▶ Sample ──▶ write
//! (io/)    (mesh/)        (mesh/)      (spline/)       (fit/)  (validity/)  (sample/)   (io/)
//! ```
//!
//! Under all of them, the foundation layer [`math`]: Bernstein and Lagrange bases, Gauss rules,
//! 3-vectors and 3×3 matrices on glam.
//!
//! ```no_run
//! use polyspline::{io::read_mesh, mesh::{MeshOptions, Topology}};
//! let mesh = read_mesh("meshes/real/mfem/cylinder-hex.mesh".as_ref(), &MeshOptions::default())?;
//! let topo = Topology::build(&mesh);
//! println!("{} hexes, {} boundary faces", mesh.n_elements(), topo.boundary_facets.len());
//! # Ok::<(), polyspline::io::ReadError>(())
//! ```

pub mod compare;
pub mod cpu;
pub mod deviation;
pub mod distributed;
pub mod elastic;
pub mod energy;
pub mod executor;
pub mod fit;
pub mod gpu;
pub mod info;
pub mod io;
pub mod math;
pub mod mesh;
pub mod params;
pub mod pipeline;
pub mod plot;
pub mod progress;
pub mod quality;
pub mod sample;
pub mod solve;
pub mod spline;
pub mod validity;
