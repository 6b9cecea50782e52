//! The binary's entry under `mpirun` (feature `mpi`): MPI is initialised only when the
//! process was started by an MPI launcher with more than one rank, so `polyspline curve`
//! without mpirun, and `mpirun -np 1`, run the serial job unchanged.

use super::comm::{Comm, Mpi};
use super::job::{DistributedReport, curve as curve_job};
use super::write::{WriteOptions, write_collective};
use crate::io::gmsh_write::MshVersion;
use crate::io::high_order::OutputFormat;
use crate::pipeline::{CurveError, CurveOptions};
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
    Written(Box<DistributedReport>),
    /// Another rank: its share is done.
    Share,
}

/// Run `curve` distributed: initialise MPI, run the job, write the output collectively (and
/// the JSON report on rank 0), finalise MPI. An error on a rank other than 0 ends that process after
/// MPI is finalised, silently: with status 0 for an option error (rank 0 has the same one and
/// reports it), else with status 1.
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
    let result = run(&comm, input, output, options, report, inputs, partitioned);
    drop(comm);
    drop(universe);
    match result {
        // Option errors are the same on every rank: rank 0 prints the line and sets the job's
        // status. The others end quietly, since an early non-zero exit lets the launcher kill
        // rank 0 before it has printed.
        Err(CurveError::Options(_)) if rank != 0 => std::process::exit(0),
        // Every read error of a partitioned input is agreed by all ranks
        // (`read_parts`): rank 0 prints it, the others end quietly for the same reason.
        Err(CurveError::Read(_)) if rank != 0 && super::read_parts::is_partitioned(input) => {
            std::process::exit(0)
        }
        Err(_) if rank != 0 => std::process::exit(1),
        r => r,
    }
}

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
    check_output(output, options)?;
    let finished = curve_job(comm, input, options)?;
    let t = std::time::Instant::now();
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
            t,
        )?;
        return Ok(r.map_or(Outcome::Share, |r| Outcome::Written(Box::new(r))));
    }
    let pending = match write_collective(comm, &finished.output, output, inputs, &write_options) {
        Ok(p) => p,
        // Rank 0 prints the error line; the others end quietly (see [`curve`]).
        Err(e) if comm.rank() == 0 => return Err(e.into()),
        Err(e) => return Err(CurveError::Options(e.to_string())),
    };
    let Some(pending) = pending else {
        return Ok(Outcome::Share);
    };
    let mut r = finished.report;
    r.curve.output = output.to_owned();
    r.curve
        .timings
        .insert("write".into(), t.elapsed().as_secs_f64());
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
