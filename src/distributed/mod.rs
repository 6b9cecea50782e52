//! Curving across MPI ranks (`--features mpi`, `mpirun -np N polyspline curve …`).
//!
//! [`comm`] is the communication layer (rsmpi over the system MPI, or one process),
//! [`read`] and [`share`] each rank's share of the input (its Morton part of the elements
//! and the ghosts around it; [`read_parts`] and [`part_file`] the same from Gmsh's
//! partitioned files; all of them parse with `io::gmsh`, the one MSH parser family, and keep
//! only who reads what), [`partition`] the element partition along a Morton curve, [`cg`] the fit's CG across ranks
//! (halo exchange of shared control points, global reductions) with [`blocks`] the serial
//! block preconditioners across the shares, [`knots`] the graded knot intervals of the whole
//! mesh (its knot surfaces joined on rank 0), [`job`] the `curve` job
//! stage by stage, [`mod@write`] the one output file written collectively and [`write_parts`]
//! Gmsh's partitioned output (one file per rank), [`periodic`] the periodic pairs across ranks
//! (resolved over the whole mesh, the image sides' nodes made the transform of the masters'). `docs/distributed.md` states what is distributed, what is replicated on
//! every rank so far, and the measured volumes.

pub mod blocks;
pub mod cg;
pub mod comm;
pub mod features;
pub mod job;
pub mod knots;
#[cfg(feature = "mpi")]
pub mod launch;
pub mod local;
pub mod part_file;
pub mod partition;
pub mod periodic;
pub mod read;
pub mod read_parts;
pub mod sample;
pub mod share;
pub mod write;
pub mod write_parts;
