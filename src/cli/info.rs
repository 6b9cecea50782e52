//! `polyspline info`: size, topology, quality, sharp features (as `curve` sees them, with
//! translation-periodic seams interior) and periodic pairs of a linear mesh.

use super::{FeatureArgs, KnotArgs};
use polyspline::info::MeshInfo;
use polyspline::io::read_mesh;
use polyspline::mesh::{MeshOptions, Topology};
use polyspline::spline::seam;
use std::path::PathBuf;

#[derive(clap::Args)]
pub(super) struct Args {
    /// Mesh file (.msh, .mesh, .vtk, .vtu, .su2, .inp, .exo).
    mesh: PathBuf,
    /// Print one JSON object instead of a table.
    #[arg(long)]
    json: bool,
    /// Keep tangled or degenerate elements instead of failing.
    #[arg(long)]
    allow_invalid: bool,
    #[command(flatten)]
    features: FeatureArgs,
    #[command(flatten)]
    knots: KnotArgs,
    /// Check that boundary A is periodic with boundary B (names or tags; repeatable) and
    /// report the transform. Pairs of the file's Gmsh `$Periodic` section are checked and
    /// reported too.
    #[arg(long, value_name = "A:B")]
    periodic: Vec<polyspline::mesh::periodic::PeriodicSpec>,
}

pub(super) fn run(args: Args) -> anyhow::Result<()> {
    let options = MeshOptions {
        allow_invalid: args.allow_invalid,
    };
    let linear = read_mesh(&args.mesh, &options)?;
    let topo = Topology::build(&linear);
    let pairs = polyspline::mesh::periodic::resolve(&linear, &topo, &args.periodic)
        .map_err(|e| anyhow::anyhow!("{}: {e}", args.mesh.display()))?;
    let knots = args.knots.params();
    // Features as `curve` finds them: where it glues the translation seams, a seam is
    // interior and no feature.
    let glued = seam::glue(&linear, &pairs);
    let view = glued
        .as_ref()
        .map(|g| seam::interior_view(&linear, &topo, g));
    let feature_topo = view.as_ref().map_or(&topo, |v| &v.topo);
    let feature_options = args.features.options();
    let found = feature_options.detect(&linear, feature_topo)?;
    let mut info = MeshInfo::new(&linear, &topo);
    info.features = Some(found.summary(&feature_options.params, feature_topo));
    // The spline space as `curve` builds it: on the glued mesh, knots measured across seams.
    info.set_spline_space(&linear, &topo, glued.as_ref(), &knots)?;
    let (lo, hi) = linear.bounding_box();
    let diagonal =
        ((hi[0] - lo[0]).powi(2) + (hi[1] - lo[1]).powi(2) + (hi[2] - lo[2]).powi(2)).sqrt();
    info.periodic = pairs.iter().map(|p| p.summary(diagonal)).collect();
    if args.json {
        println!("{}", serde_json::to_string_pretty(&info)?);
    } else {
        println!("{:<22}{}", "mesh", args.mesh.display());
        print!("{info}");
    }
    Ok(())
}
