//! The binary's entry under `mpirun` (feature `mpi`): MPI is initialised only when the
//! process was started by an MPI launcher with more than one rank, so `polyspline curve`
//! without mpirun, and `mpirun -np 1`, run the serial job unchanged.

use super::comm::{Comm, Mpi};
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

/// Under mpirun with several ranks, end a rank other than 0 quietly (status 0) on an error
/// every rank finds before the job starts (an output path, an option): rank 0 prints the
/// one error line and sets the job's status. Returns the error on rank 0 and outside mpirun.
pub fn quiet_unless_rank_0<E>(e: E) -> E {
    if distributed() && launched_rank().is_some_and(|r| r != 0) {
        std::process::exit(0);
    }
    e
}

/// Whether `curve` should run distributed: under an MPI launcher with more than one rank.
pub fn distributed() -> bool {
    launched_size().is_some_and(|n| n > 1)
}

/// What [`curve`] did on this rank.
pub enum Outcome {
    /// Rank 0: the output (and report) were written.
    Written(Box<CurveReport>),
    /// Another rank: its share is done.
    Share,
}

/// Run `curve` distributed: initialise MPI, run the job, write the output collectively (and
/// the JSON report on rank 0), finalise MPI. On an error every rank ends with status 1 and
/// the job prints one error line: the lowest rank whose stage failed prints it (agreed by
/// [`super::comm::agree`]), or rank 0 for an error every rank finds alike (an option, the
/// output, the solve). The line is printed before MPI is finalised, and the ranks wait for
/// each other there, so no rank's exit lets the launcher kill the printing rank first.
pub fn curve(
    input: &Path,
    output: &Path,
    options: &CurveOptions,
    report: Option<&Path>,
    inputs: &[&Path],
    partitioned: bool,
) -> Result<Outcome, CurveError> {
    let universe = mpi::initialize()
        .ok_or_else(|| CurveError::Options("MPI was initialised already in this process".into()))?;
    let comm = Mpi::new(universe.world());
    let rank = comm.rank();
    // A panic is a bug, but on one rank it would leave the others waiting in a collective for
    // ever: after its message, end the whole job.
    let report_panic = std::panic::take_hook();
    std::panic::set_hook(Box::new(move |info| {
        report_panic(info);
        use mpi::topology::Communicator;
        mpi::topology::SimpleCommunicator::world().abort(70);
    }));
    let result = run(&comm, input, output, options, report, inputs, partitioned);
    let failed = result.is_err();
    if failed {
        FAILED.store(true, std::sync::atomic::Ordering::Relaxed);
    }
    if let Err(e) = &result
        && rank == super::comm::failing_rank().unwrap_or(0)
    {
        eprintln!(
            "polyspline: error: {}",
            crate::mesh::raw::one_line(&e.to_string(), MAX_ERROR_CHARS)
        );
    }
    // Every rank is here (an error is agreed or alike on every rank): the line is out before
    // any rank ends.
    let mut done = [0u64];
    comm.sum_u64(&mut done);
    drop(comm);
    drop(universe);
    if failed {
        std::process::exit(1);
    }
    result
}

/// Set once this rank knows the job failed (its error line is printed or is another rank's).
static FAILED: std::sync::atomic::AtomicBool = std::sync::atomic::AtomicBool::new(false);

/// Whether this process is a rank of a distributed job that failed and is ending: the launcher
/// may stop it with a signal before it exits, which needs no message of its own.
pub fn failed() -> bool {
    FAILED.load(std::sync::atomic::Ordering::Relaxed)
}

/// Longest error line (characters after the prefix), as the serial command's.
const MAX_ERROR_CHARS: usize = 2000;

/// The output options the collective writer takes: one MSH 4.1 file (ASCII or binary).
fn check_output(output: &Path, options: &CurveOptions) -> Result<(), CurveError> {
    let refuse = |what: &str| {
        Err(CurveError::Options(format!(
            "{what} is not available under mpirun yet (docs/distributed.md); run it on one process"
        )))
    };
    if OutputFormat::from_path(output) != Some(OutputFormat::Msh) {
        return refuse("an output other than .msh");
    }
    if options.output.msh_version != MshVersion::V41 {
        return refuse("--msh-version 2.2");
    }
    if options.output.vtu_boundary.is_some() {
        return refuse("--vtu-boundary");
    }
    Ok(())
}

fn run(
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
    // Its errors are alike on every rank (one sum); rank 0 prints the line (see [`curve`]).
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
