//! Option groups several subcommands share (and the Python package's `curve`, which builds
//! the same groups from keyword arguments): the elastic analogy and sharp features.

use super::values;
use polyspline::elastic::ElasticParams;
use polyspline::mesh::features::FeatureParams;
use polyspline::mesh::periodic::PeriodicSpec;
use polyspline::pipeline::{FeatureOptions, PeriodicOptions};
use polyspline::solve::CgParams;
use polyspline::spline::{KnotIntervals, KnotParams};
use std::path::PathBuf;

/// Material and solver of the elastic analogy.
#[derive(clap::Args)]
pub(crate) struct ElasticArgs {
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
    /// `--elastic-solver`.
    pub(crate) fn solver(&self) -> values::ElasticSolver {
        self.elastic_solver
    }

    /// The elastic analogy's parameters; `cg_tol` is `--cg-tol` (default: the elastic CG's).
    pub(crate) fn params(&self, cg_tol: Option<f64>) -> ElasticParams {
        ElasticParams {
            young: self.young,
            poisson: self.poisson,
            cg: CgParams {
                rel_tol: cg_tol.unwrap_or(CgParams::default().rel_tol),
                ..Default::default()
            },
            preconditioner: self.elastic_preconditioner.into(),
            solver: self.elastic_solver.into(),
            stiffening: self.elastic_stiffening,
        }
    }
}

/// Knot intervals of the spline elements (`polyspline::spline::intervals`).
#[derive(clap::Args)]
pub(crate) struct KnotArgs {
    /// Knot intervals of the spline elements.
    #[arg(long, value_enum, default_value_t = KnotIntervals::default().into())]
    knot_intervals: values::KnotIntervals,
    /// With graded knot intervals: the largest ratio of neighbouring intervals (larger ones are
    /// clamped to it); a knot surface whose cells' ratio exceeds its cube is split (the
    /// elements along it Q2, C⁰ there).
    #[arg(long, default_value_t = KnotParams::default().max_ratio, value_name = "R")]
    knot_max_ratio: f64,
    /// With graded knot intervals: the largest spread (max − min) of the measured
    /// log-ratios of cells across one knot surface; where a surface's cells vary more, it is
    /// split and the elements on both sides of the split become Q2 (C⁰ there). `inf`: one
    /// ratio per surface, never split.
    #[arg(long, default_value_t = KnotParams::default().max_spread, value_name = "S")]
    knot_max_spread: f64,
}

impl KnotArgs {
    /// Whether `--knot-intervals uniform` was chosen (no interval is graded).
    pub(crate) fn uniform(&self) -> bool {
        self.knot_intervals == values::KnotIntervals::Uniform
    }

    pub(crate) fn params(&self) -> KnotParams {
        KnotParams {
            intervals: self.knot_intervals.into(),
            max_ratio: self.knot_max_ratio,
            max_spread: self.knot_max_spread,
        }
    }
}

/// Sharp feature detection (`docs/features.md`).
#[derive(clap::Args)]
pub(crate) struct FeatureArgs {
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
    pub(crate) feature_edits: Option<PathBuf>,
    /// Detect and report the features but curve as if the boundary were smooth everywhere
    /// (for comparisons).
    #[arg(long)]
    ignore_features: bool,
}

impl FeatureArgs {
    pub(crate) fn options(&self) -> FeatureOptions {
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

/// Periodic boundary pairs (`docs/periodic.md`).
#[derive(clap::Args)]
pub(crate) struct PeriodicArgs {
    /// Boundary A is periodic with boundary B (names or tags; repeatable): the transform, a
    /// translation or a rotation, is found from the vertex positions and verified, and the
    /// written nodes of B are exactly the transform of A's. Pairs of the input's Gmsh
    /// `$Periodic` section are used without this option; a pair given here wins over the
    /// file's for its groups.
    #[arg(long, value_name = "A:B")]
    periodic: Vec<PeriodicSpec>,
    /// Write pair i's groups as `periodic_<i>_l` (A) and `periodic_<i>_r` (B), the names
    /// PyFR's importer pairs: the pairs of --periodic, then those of the input's $Periodic.
    #[arg(long)]
    periodic_pyfr_names: bool,
}

impl PeriodicArgs {
    pub(crate) fn options(&self) -> PeriodicOptions {
        PeriodicOptions {
            pairs: self.periodic.clone(),
            pyfr_names: self.periodic_pyfr_names,
        }
    }
}
