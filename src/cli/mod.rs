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

mod check;
mod compare;
mod curve;
mod generate;
mod info;
mod plot;
mod values;

use clap::{Parser, Subcommand};
use polyspline::elastic::ElasticParams;
use polyspline::io::read_raw;
use polyspline::mesh::HighOrderMesh;
use polyspline::mesh::features::FeatureParams;
use polyspline::pipeline::FeatureOptions;
use polyspline::solve::CgParams;
use std::path::{Path, PathBuf};

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

/// Material and solver of the elastic analogy.
#[derive(clap::Args)]
struct ElasticArgs {
    /// Young's modulus of the elastic analogy.
    #[arg(long, default_value_t = 1.5)]
    young: f64,
    /// Poisson's ratio of the elastic analogy (below 0.5).
    #[arg(long, default_value_t = 0.49)]
    poisson: f64,
    /// Preconditioner of the elastic CG solve: the diagonal, the per-node d×d block inverse,
    /// or a symmetric block Gauss–Seidel sweep.
    #[arg(long, value_enum, default_value_t = values::ElasticPreconditioner::BlockJacobi)]
    elastic_preconditioner: values::ElasticPreconditioner,
    /// Solver of the elastic system: `auto` factors it (sparse Cholesky) when the factor
    /// stays under 2.4e8 entries and runs preconditioned CG otherwise; `cg` and `cholesky`
    /// force one.
    #[arg(long, value_enum, default_value_t = values::ElasticSolver::Auto)]
    elastic_solver: values::ElasticSolver,
    /// Jacobian-based stiffening exponent of the elastic analogy: the stiffness at a point
    /// is scaled by |det J|^-CHI of the straight mesh, so small cells move with the boundary
    /// (0: the paper's homogeneous material).
    #[arg(long, default_value_t = 0.0, value_name = "CHI")]
    elastic_stiffening: f64,
}

impl ElasticArgs {
    fn params(&self, cg_tol: f64) -> ElasticParams {
        ElasticParams {
            young: self.young,
            poisson: self.poisson,
            cg: CgParams {
                rel_tol: cg_tol,
                ..Default::default()
            },
            preconditioner: self.elastic_preconditioner.into(),
            solver: self.elastic_solver.into(),
            stiffening: self.elastic_stiffening,
        }
    }
}

/// Sharp feature detection (`docs/features.md`).
#[derive(clap::Args)]
struct FeatureArgs {
    /// Boundary facets whose normals differ by more than this angle (degrees; 2D: boundary
    /// turning angle) meet at a sharp feature; 180 finds none by angle.
    #[arg(long, default_value_t = 35.0, value_name = "DEG")]
    feature_angle: f64,
    /// Do not make the boundaries between differently tagged boundary regions features.
    #[arg(long)]
    no_feature_tags: bool,
    /// Add or remove features: lines `add I J` / `remove I J` (3D edges) or `add I` /
    /// `remove I` (2D corners), 0-based vertex ids.
    #[arg(long, value_name = "FILE")]
    feature_edits: Option<PathBuf>,
    /// Detect and report the features but curve as if the boundary were smooth everywhere
    /// (for comparisons).
    #[arg(long)]
    ignore_features: bool,
}

impl FeatureArgs {
    fn options(&self) -> FeatureOptions {
        FeatureOptions {
            params: FeatureParams {
                angle_deg: self.feature_angle,
                tags: !self.no_feature_tags,
            },
            edits: self.feature_edits.clone(),
            ignore: self.ignore_features,
        }
    }
}

/// Read a high-order mesh written by `curve` (or any linear/Lagrange quad/hex mesh).
fn read_high_order(path: &Path) -> anyhow::Result<HighOrderMesh> {
    let raw = read_raw(path)?;
    HighOrderMesh::from_raw(raw)
        .map_err(|e| anyhow::anyhow!("{}: {}: {}", path.display(), e.location, e.message))
}
