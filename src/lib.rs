//! polyspline: curved high-order quad/hex meshes from linear ones, without CAD.
//!
//! The pipeline (stages and seams: `docs/architecture.md`):
//!
//! ```text
//! read ──▶ LinearMesh ──▶ Topology ──▶ SplineSpace ──▶ Fit ──▶ Validity ──▶ Sample ──▶ write
//! (io/)    (mesh/)        (mesh/)      (spline/)       (fit/)  (validity/)  (sample/)   (io/)
//! ```
//!
//! The modules stand on floors, each using only its own floor and those below it: foundation
//! ([`math`], [`params`], [`progress`]) → [`mesh`] → [`io`] beside the algorithms ([`spline`],
//! [`fit`], [`validity`], [`energy`], [`sample`], ...) → execution ([`exec`]: the CPU and GPU
//! executors) → jobs ([`pipeline`], [`compare`], [`distributed`]) → the command line. Under
//! all of them, the foundation [`math`]: Bernstein and Lagrange bases, Gauss rules, the
//! reference element, 3-vectors and 3×3 matrices on glam.
//!
//! ```no_run
//! use polyspline::{io::read_mesh, mesh::{MeshOptions, Topology}};
//! let mesh = read_mesh("meshes/real/mfem/cylinder-hex.mesh".as_ref(), &MeshOptions::default())?;
//! let topo = Topology::build(&mesh);
//! println!("{} hexes, {} boundary faces", mesh.n_elements(), topo.boundary_facets.len());
//! # Ok::<(), polyspline::io::ReadError>(())
//! ```

// The floors, bottom up: a module uses only its own floor and those below it, and no two
// top-level modules import each other (`scripts/check_floors.py` holds the table and the
// `library` tests run it).

// Foundation: what every floor may use.
pub mod math; // Bernstein/Lagrange bases, Gauss rules, reference quad and hex, 3×3 algebra.
pub mod params; // `ParamError` and the range checks every options struct validates itself with.
pub mod progress; // The stages of the `curve` job and the receiver of their progress.

// Mesh: the meshes themselves.
pub mod mesh; // Raw reader output, linear and high-order meshes, topology, features, generators.

// IO: files in and out (beside the algorithms, not above them).
pub mod io; // Readers of ten mesh formats; MSH, VTU, CGNS, Abaqus writers; node orderings.
pub mod plot; // SVG drawings of 2D meshes.

// Algorithms: the method, on meshes, knowing nothing of files, devices or jobs.
pub mod deviation; // Deviation of the curved boundary from the input's linear boundary.
pub mod elastic; // The elastic analogy (the baseline method).
pub mod energy; // The degeneration energy and its minimisers, over a narrow `EnergyKernel`.
pub mod fit; // Least-squares fit of the spline control points.
pub mod info; // The `info` summary of a linear mesh.
pub mod quality; // Sampled Jacobian quality of high-order elements.
pub mod sample; // Sampling element maps into a conforming high-order mesh.
pub mod solve; // Linear solvers: preconditioned CG and sparse Cholesky.
pub mod spline; // The quadratic poly-spline space on the mesh.
pub mod validity; // Certified det J bounds, line searches, the blend, snapping; over a `Certifier`.

// Execution: where the heavy work runs.
pub mod exec; // The `Executor` trait; the CPU reference with the kernels' CPU twins; the GPU.

// Jobs: the stages composed into what a user runs.
pub mod compare; // Every method on one mesh in one table.
pub mod distributed; // The curve job on many processes (`--features mpi`).
pub mod pipeline; // The `curve` job: its options, stages and report.

// The command line (`src/cli/`, in the binary) is the top floor.
