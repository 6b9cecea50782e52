//! `polyspline check`: validity and quality of a high-order mesh.
//!
//! Output: the report (a table, or JSON with `--json`) and the exit status: 0 when every
//! element is valid, [`EXIT_INVALID_MESH`] when any has a sampled det J ≤ 0, so the command
//! can gate a script or a CI step.

use super::{EXIT_INVALID_MESH, read_high_order};
use polyspline::quality::CheckReport;
use std::path::PathBuf;

#[derive(clap::Args)]
pub(super) struct Args {
    /// High-order mesh file.
    mesh: PathBuf,
    /// Print one JSON object instead of a table.
    #[arg(long)]
    json: bool,
}

pub(super) fn run(args: Args) -> anyhow::Result<u8> {
    let ho = read_high_order(&args.mesh)?;
    let report = CheckReport::new(&ho);
    let status = if report.invalid > 0 {
        EXIT_INVALID_MESH
    } else {
        0
    };
    if args.json {
        println!("{}", serde_json::to_string_pretty(&report)?);
        return Ok(status);
    }
    println!("{:<22}{}", "mesh", args.mesh.display());
    println!(
        "{:<22}{} ({}D, order {})",
        "elements", report.elements, report.dimension, report.order
    );
    println!("{:<22}{}", "nodes", report.nodes);
    println!("{:<22}{}", "boundary facets", report.boundary_facets);
    println!("{:<22}{}", "invalid elements", report.invalid);
    println!(
        "{:<22}{:.6} (element {})",
        "min scaled Jacobian", report.min_scaled_jacobian, report.worst_element
    );
    println!("{:<22}{:.6e}", "min det J", report.min_det_jacobian);
    println!("{:<22}{}", "method", report.method);
    Ok(status)
}
