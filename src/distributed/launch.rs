//! Where the binary's `curve` meets the distributed job (feature `mpi`): whether this process
//! was started by an MPI launcher with more than one rank (MPI is initialised only then, so
//! `polyspline curve` without mpirun, and `mpirun -np 1`, run the serial job unchanged), and
//! the job run and written on an initialised communicator ([`curve_and_write`]).
//!
//! Input: the launcher's environment; a communicator, the input and output paths and the
//! options. Output: the output file written collectively (or Gmsh's parts) and the report on
//! rank 0, or the job's error on every rank. Invariant: nothing here prints or exits; the
//! binary's launcher (`cli/launch.rs`) initialises MPI, prints the one error line from the
//! failing rank and sets the status.

use super::comm::Comm;
use super::job::curve as curve_job;
use super::write::{WriteOptions, write_collective};
use crate::io::gmsh_write::MshVersion;
use crate::io::high_order::OutputFormat;
use crate::pipeline::{CurveError, CurveOptions, CurveReport};
use std::path::Path;

/// The number of ranks of the MPI job this process belongs to, from the launcher's
/// environment (Open MPI, MPICH/Hydra, PMIx), or `None` outside one.
pub fn launched_size() -> Option<usize> {
    ["OMPI_COMM_WORLD_SIZE", "PMI_SIZE", "PMIX_SIZE"]
        .iter()
        .find_map(|v| std::env::var(v).ok()?.parse().ok())
}

/// This process's rank in the MPI job, from the launcher's environment, or `None` outside one.
pub fn launched_rank() -> Option<usize> {
    ["OMPI_COMM_WORLD_RANK", "PMI_RANK", "PMIX_RANK"]
        .iter()
        .find_map(|v| std::env::var(v).ok()?.parse().ok())
}

/// Whether `curve` should run distributed: under an MPI launcher with more than one rank.
pub fn distributed() -> bool {
    launched_size().is_some_and(|n| n > 1)
}

/// MPI for one job: initialised by [`World::initialize`], finalised when dropped (after the
/// communicator, which is dropped first).
pub struct World {
    comm: super::comm::Mpi,
    _universe: mpi::environment::Universe,
}

impl World {
    /// Initialise MPI; an error if this process initialised it already.
    pub fn initialize() -> Result<World, CurveError> {
        let universe = mpi::initialize().ok_or_else(|| {
            CurveError::Options("MPI was initialised already in this process".into())
        })?;
        Ok(World {
            comm: super::comm::Mpi::new(universe.world()),
            _universe: universe,
        })
    }

    /// The communicator of every rank of the job.
    pub fn comm(&self) -> &super::comm::Mpi {
        &self.comm
    }

    /// End every rank of the job at once (`MPI_Abort` with `code`): for a panic on one rank,
    /// which would otherwise leave the others waiting in a collective for ever.
    pub fn abort_all(code: i32) -> ! {
        use mpi::topology::Communicator;
        mpi::topology::SimpleCommunicator::world().abort(code)
    }
}

/// What [`curve_and_write`] did on this rank.
pub enum Outcome {
    /// Rank 0: the output (and report) were written.
    Written(Box<CurveReport>),
    /// Another rank: its share is done.
    Share,
}

/// The output options the collective writer takes: one MSH 4.1 file (ASCII or binary). Every
/// output option is named (none left to `..`), so one added later does not compile until it
/// is written or refused here.
fn check_output(output: &Path, options: &CurveOptions) -> Result<(), CurveError> {
    let refuse = |what: &str| {
        Err(CurveError::Options(format!(
            "{what} is not available under mpirun yet (docs/distributed.md); run it on one process"
        )))
    };
    // `_`: written by the collective writers (`vtu_encoding`: a VTU output's only, refused
    // below with the format).
    let crate::io::high_order::OutputOptions {
        msh_version,
        binary: _,
        vtu_encoding: _,
        volume_name: _,
        vtu_boundary,
    } = &options.output;
    if OutputFormat::from_path(output) != Some(OutputFormat::Msh) {
        return refuse("an output other than .msh");
    }
    if *msh_version != MshVersion::V41 {
        return refuse("--msh-version 2.2");
    }
    if vtu_boundary.is_some() {
        return refuse("--vtu-boundary");
    }
    Ok(())
}

/// Run the `curve` job over `comm` and write its output collectively (one MSH 4.1 file, or
/// with `partitioned` Gmsh's part files) and the JSON report on rank 0. An error is returned on
/// every rank; which rank's is printed is the caller's ([`super::comm::failing_rank`]).
pub fn curve_and_write(
    comm: &dyn Comm,
    input: &Path,
    output: &Path,
    options: &CurveOptions,
    report: Option<&Path>,
    inputs: &[&Path],
    partitioned: bool,
) -> Result<Outcome, CurveError> {
    let start = std::time::Instant::now();
    check_output(output, options)?;
    if partitioned && !options.periodic.pairs.is_empty() {
        return Err(CurveError::Options(
            "--periodic with --partitioned is not available yet (docs/distributed.md): write one file".into(),
        ));
    }
    let finished = curve_job(comm, input, options)?;
    let write_options = WriteOptions {
        binary: options.output.binary,
        volume_name: &options.output.volume_name,
        tag_names: &finished.tag_names,
    };
    if partitioned {
        let r = super::write_parts::write_all(
            comm,
            &finished.output,
            finished.report,
            output,
            report,
            inputs,
            &write_options,
            start,
        )?;
        return Ok(r.map_or(Outcome::Share, |r| Outcome::Written(Box::new(r))));
    }
    // Its errors are alike on every rank (one sum); rank 0 prints the line (the binary's launcher).
    let write_started = std::time::Instant::now();
    let pending = write_collective(comm, &finished.output, output, inputs, &write_options)?;
    let Some(pending) = pending else {
        return Ok(Outcome::Share);
    };
    let mut r = finished.report;
    r.written(output, write_started, start);
    let pending_report = match report {
        Some(path) => {
            let json = serde_json::to_string_pretty(&r).expect("the report serialises");
            Some(crate::io::output::prepare(path, inputs, |w| {
                use std::io::Write;
                writeln!(w, "{json}")
            })?)
        }
        None => None,
    };
    pending.commit()?;
    if let Some(p) = pending_report {
        p.commit()?;
    }
    Ok(Outcome::Written(Box::new(r)))
}
