//! The `polyspline` command line: one module per subcommand, each parsing its options into
//! the library's option structs and running the library's job.
//!
//! Input: the process arguments (parsed by clap). Output: the job's files and the lines it
//! prints, or an error for `main` to print as one bounded line (exit status 1; clap's own
//! usage errors exit with 2). `check` exits with 3 ([`EXIT_INVALID_MESH`]) when it finds an
//! invalid element.
//!
//! Invariant: no option is validated here; the library refuses bad values (each options
//! struct's `check`, over [`polyspline::params`], and the generators and readers for their own
//! inputs), so a caller of the library is refused as the command line is. The enumerated
//! values are spelled here ([`values`]), so the library carries no clap types.

mod args;
mod check;
mod compare;
mod curve;
mod generate;
mod info;
#[cfg(feature = "mpi")]
pub(crate) mod launch;
mod plot;
mod values;

use args::{ElasticArgs, FeatureArgs, KnotArgs, PeriodicArgs};
use clap::{CommandFactory, FromArgMatches, Parser, Subcommand};
use polyspline::io::read_raw;
use polyspline::mesh::HighOrderMesh;
use std::path::Path;

#[derive(Parser)]
#[command(
    name = "polyspline",
    version,
    about = "Curved high-order quad/hex meshes from linear ones, without CAD"
)]
pub struct Cli {
    #[command(subcommand)]
    command: Command,
}

// Parsed once per run: the size of the largest variant (`curve`'s options) does not matter.
#[allow(clippy::large_enum_variant)]
#[derive(Subcommand)]
enum Command {
    /// Read a linear quad/hex mesh and report its size, topology and quality.
    Info(info::Args),
    /// Make a curved high-order mesh from a linear quad/hex mesh.
    Curve(curve::Args),
    /// Curve one mesh with every method (straight, IGA with the position, frame and smooth
    /// fits, elastic analogy) and print one table: times, validity, quality, boundary
    /// deviation and the facet angle jump (docs/compare.md). Writes nothing.
    Compare(compare::Args),
    /// Make a synthetic linear mesh with curved boundaries for benchmarks: a butterfly disc
    /// (2D), a solid cylinder or a torus (3D), with valence-3 vertices/edges; or a
    /// boundary-layer O-grid (ellipse, circle, NACA 00xx) or C-grid (NACA 00xx with a wake cut).
    Generate(generate::Args),
    /// Report the validity and quality of a high-order mesh (.msh or .vtu). Exit status: 0 when
    /// every element is valid, 3 when any element has a sampled det J ≤ 0, 1 on an error.
    Check(check::Args),
    /// Draw a 2D mesh (linear or high order) as SVG, with curved edges drawn as curves.
    Plot(plot::Args),
}

/// Exit status of `check` when the mesh has an invalid element (sampled det J ≤ 0): distinct
/// from 1 (an error) and 2 (a usage error), so a script can tell a bad mesh from a failed run.
pub const EXIT_INVALID_MESH: u8 = 3;

/// The process arguments, parsed; `curve` also records which options were given, so that it
/// can refuse one given where the job cannot use it (clap errors exit as [`Parser::parse`]'s).
pub fn parse() -> Cli {
    let matches = Cli::command().get_matches();
    let mut cli = Cli::from_arg_matches(&matches).unwrap_or_else(|e| e.exit());
    if let (Command::Curve(args), Some(("curve", m))) = (&mut cli.command, matches.subcommand()) {
        args.record_given(m);
    }
    cli
}

/// Run the parsed command: the process's exit status on success (0, or
/// [`EXIT_INVALID_MESH`] from `check`).
pub fn run(cli: Cli) -> anyhow::Result<u8> {
    let done = |r: anyhow::Result<()>| r.map(|()| 0);
    match cli.command {
        Command::Info(args) => done(info::run(args)),
        Command::Curve(args) => done(curve::run(args)),
        Command::Compare(args) => done(compare::run(args)),
        Command::Generate(args) => done(generate::run(args)),
        Command::Check(args) => check::run(args),
        Command::Plot(args) => done(plot::run(args)),
    }
}

/// Read a high-order mesh written by `curve` (or any linear/Lagrange quad/hex mesh).
fn read_high_order(path: &Path) -> anyhow::Result<HighOrderMesh> {
    let raw = read_raw(path)?;
    HighOrderMesh::from_raw(raw)
        .map_err(|e| anyhow::anyhow!("{}: {}: {}", path.display(), e.location, e.message))
}
