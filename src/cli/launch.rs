//! The `curve` job under mpirun (feature `mpi`): MPI initialised for the job and finalised
//! after it, one error line from the rank whose stage failed, the exit status of every rank.
//!
//! Input: the prepared job's paths and options. Output: [`polyspline::distributed::launch::Outcome`]
//! on success; on an error every rank ends with status 1 after the line is printed.
//! Invariant: the library's distributed job neither prints nor exits; this is where a rank does.

use polyspline::distributed::comm::{Comm, failing_rank};
use polyspline::distributed::launch::{
    Outcome, World, curve_and_write, distributed, launched_rank,
};
use polyspline::pipeline::{CurveError, CurveOptions};
use std::path::Path;

/// Under mpirun with several ranks, end a rank other than 0 quietly (status 0) on an error
/// every rank finds before the job starts (an output path, an option): rank 0 prints the
/// one error line and sets the job's status. Returns the error on rank 0 and outside mpirun.
pub(crate) fn quiet_unless_rank_0<E>(e: E) -> E {
    if distributed() && launched_rank().is_some_and(|r| r != 0) {
        std::process::exit(0);
    }
    e
}

/// Run `curve` distributed: initialise MPI, run the job, write the output collectively (and
/// the JSON report on rank 0), finalise MPI. On an error every rank ends with status 1 and
/// the job prints one error line: the lowest rank whose stage failed prints it (agreed by
/// [`polyspline::distributed::comm::agree`]), or rank 0 for an error every rank finds alike (an option, the
/// output, the solve). The line is printed before MPI is finalised, and the ranks wait for
/// each other there, so no rank's exit lets the launcher kill the printing rank first.
pub(crate) fn curve(
    input: &Path,
    output: &Path,
    options: &CurveOptions,
    report: Option<&Path>,
    inputs: &[&Path],
    partitioned: bool,
) -> Result<Outcome, CurveError> {
    let world = World::initialize()?;
    let comm = world.comm();
    let rank = comm.rank();
    // A panic is a bug, but on one rank it would leave the others waiting in a collective for
    // ever: after its message, end the whole job.
    let report_panic = std::panic::take_hook();
    std::panic::set_hook(Box::new(move |info| {
        report_panic(info);
        World::abort_all(70);
    }));
    let result = curve_and_write(comm, input, output, options, report, inputs, partitioned);
    let failed = result.is_err();
    if failed {
        FAILED.store(true, std::sync::atomic::Ordering::Relaxed);
    }
    if let Err(e) = &result
        && rank == failing_rank().unwrap_or(0)
    {
        eprintln!(
            "polyspline: error: {}",
            polyspline::mesh::raw::one_line(&e.to_string(), MAX_ERROR_CHARS)
        );
    }
    // Every rank is here (an error is agreed or alike on every rank): the line is out before
    // any rank ends.
    let mut done = [0u64];
    comm.sum_u64(&mut done);
    drop(world);
    if failed {
        std::process::exit(1);
    }
    result
}

/// Set once this rank knows the job failed (its error line is printed or is another rank's).
static FAILED: std::sync::atomic::AtomicBool = std::sync::atomic::AtomicBool::new(false);

/// Whether this process is a rank of a distributed job that failed and is ending: the launcher
/// may stop it with a signal before it exits, which needs no message of its own.
pub(crate) fn failed() -> bool {
    FAILED.load(std::sync::atomic::Ordering::Relaxed)
}

/// Longest error line (characters after the prefix), as the serial command's.
const MAX_ERROR_CHARS: usize = 2000;
