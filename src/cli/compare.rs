//! `polyspline compare`: every method on one mesh, one table.

use super::values;
use super::{ElasticArgs, FeatureArgs, KnotArgs};
use polyspline::compare::{CompareOptions, compare};
use polyspline::exec::gpu::BackendChoice;
use polyspline::fit::{FIT_CG_TOL, FitParams};
use polyspline::mesh::MeshOptions;
use polyspline::pipeline::CurveOptions;
use polyspline::solve::CgParams;
use std::path::PathBuf;

#[derive(clap::Args)]
pub(super) struct Args {
    /// Input mesh file.
    mesh: PathBuf,
    /// Order of the output elements.
    #[arg(long, default_value_t = 2)]
    order: usize,
    /// Print one JSON object instead of a table.
    #[arg(long)]
    json: bool,
    #[command(flatten)]
    elastic: ElasticArgs,
    /// Relative tolerance of the conjugate-gradient solves (fit and elastic analogy)
    /// [default: 1e-6, as `curve`'s].
    #[arg(long, value_name = "CG_TOL")]
    cg_tol: Option<f64>,
    /// Keep tangled or degenerate input elements instead of failing.
    #[arg(long)]
    allow_invalid: bool,
    /// Where sampling, certification and the fit's CG solve run (the elastic solve runs on
    /// the CPU).
    #[arg(long, value_enum, default_value_t = values::BackendChoice::Cpu)]
    backend: values::BackendChoice,
    #[command(flatten)]
    features: FeatureArgs,
    #[command(flatten)]
    knots: KnotArgs,
}

pub(super) fn run(args: Args) -> anyhow::Result<()> {
    let options = CompareOptions {
        base: CurveOptions {
            order: args.order,
            fit: FitParams {
                cg: CgParams {
                    rel_tol: args.cg_tol.unwrap_or(FIT_CG_TOL),
                    ..Default::default()
                },
                ..FitParams::smooth()
            },
            mesh: MeshOptions {
                allow_invalid: args.allow_invalid,
            },
            backend: BackendChoice::from(args.backend).resolve(None)?,
            features: args.features.options(),
            knots: args.knots.params(),
            ..Default::default()
        },
        elastic: args.elastic.params(args.cg_tol),
    };
    let report = compare(&args.mesh, &options)?;
    if args.json {
        println!("{}", serde_json::to_string_pretty(&report)?);
    } else {
        print!("{report}");
    }
    Ok(())
}
