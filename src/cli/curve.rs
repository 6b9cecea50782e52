//! `polyspline curve`: the curved high-order mesh of a linear one, and its report.
//!
//! The options come in groups that the Python package shares (it builds them from keyword
//! arguments with the same names, so both front ends validate and default alike):
//! [`JobArgs`] (how to curve), [`OutputArgs`] (how to write) and [`FileArgs`] (the files).
//! [`prepare_files`] refuses bad options and outputs before any work; [`curve_files`] runs
//! the job on one process and writes the mesh and the report.

use super::values;
use super::{ElasticArgs, FeatureArgs, KnotArgs, PeriodicArgs};
use polyspline::elastic::ElasticSolver;
use polyspline::energy::{EnergyParams, EnergySolver};
use polyspline::exec::gpu::BackendChoice;
use polyspline::fit::{
    FIT_CG_TOL, FitParams, FitPreset, FitSolver, FitTargets, FitWeights, SmoothParams,
};
use polyspline::io::output::{check_outputs, prepare};
use polyspline::mesh::MeshOptions;
use polyspline::pipeline::{
    CurveError, CurveOptions, CurveReport, Geometry, Method, OutputFormat, OutputOptions,
    curve_prepared,
};
use polyspline::progress::Progress;
use polyspline::solve::{CgParams, CgPreconditioner};
use polyspline::validity::LineSearchParams;
use std::path::{Path, PathBuf};

#[derive(clap::Args)]
pub(super) struct Args {
    #[command(flatten)]
    files: FileArgs,
    /// No progress spinner on stderr (it is also off when stderr is not a terminal).
    #[arg(short, long)]
    quiet: bool,
}

impl Args {
    /// Record which options `matches` (the subcommand's parse) holds from the command line.
    pub(super) fn record_given(&mut self, matches: &clap::ArgMatches) {
        self.files.record_given(matches);
    }
}

/// The input, the outputs, and the options of the job and of the writers.
#[derive(clap::Args)]
pub(crate) struct FileArgs {
    /// Input mesh file.
    pub(crate) mesh: PathBuf,
    /// Output file: .msh (Gmsh), .vtu (VTK Lagrange cells), .cgns (CGNS/HDF5) or .inp
    /// (Abaqus for Trixi.jl).
    #[arg(short, long)]
    pub(crate) output: PathBuf,
    /// Write a JSON report (sizes, timings) to this file.
    #[arg(long, value_name = "FILE.json")]
    pub(crate) report: Option<PathBuf>,
    /// Under mpirun: write Gmsh's partitioned MSH 4.1 files OUT_1.msh … OUT_N.msh (one per
    /// rank, read by Gmsh as one mesh) instead of one file (docs/distributed.md).
    #[arg(long)]
    partitioned: bool,
    #[command(flatten)]
    pub(crate) job: JobArgs,
    #[command(flatten)]
    pub(crate) out: OutputArgs,
}

impl FileArgs {
    /// Record which options `matches` (this group's parse) holds from the command line.
    pub(crate) fn record_given(&mut self, matches: &clap::ArgMatches) {
        self.job.record_given(matches);
        self.out.record_given(matches);
    }
}

/// How to curve: every option of the job but the files and the writers'.
#[derive(clap::Args)]
pub(crate) struct JobArgs {
    /// Order of the output elements (1-10; Gmsh hexes up to 9).
    #[arg(long, default_value_t = 2)]
    order: usize,
    /// Write the straight-sided order-P mesh of the input (no curving), for comparison.
    #[arg(long, conflicts_with_all = ["fit", "method"])]
    straight: bool,
    /// `iga` samples the fitted spline everywhere; `elastic` (the paper's baseline, §2.5)
    /// puts the boundary nodes on the same fitted spline and moves the interior nodes of the
    /// straight order-P mesh by linear elasticity.
    #[arg(long, value_enum, default_value_t = values::Method::Iga)]
    method: values::Method,
    #[command(flatten)]
    elastic: ElasticArgs,
    /// Fit of the spline control points (`smooth` is the default).
    #[arg(long, value_enum, default_value_t = values::FitPreset::Smooth)]
    fit: values::FitPreset,
    #[command(flatten)]
    energy: EnergyArgs,
    /// Position weight at interior element corners (overrides the preset).
    #[arg(long)]
    w_corner: Option<f64>,
    /// Position weight at element corners on the boundary (overrides the preset).
    #[arg(long)]
    w_boundary_corner: Option<f64>,
    /// Position weight at edge/face midpoints and element centres inside the mesh (overrides
    /// the preset).
    #[arg(long)]
    w_midpoint: Option<f64>,
    /// Position weight at the midpoints and centres of elements a ring away from the boundary
    /// (no vertex on an element touching it; default: `--w-midpoint` with uniform knots, at
    /// least 3 with graded ones).
    #[arg(long)]
    w_deep_midpoint: Option<f64>,
    /// Position weight at the interior midpoints and centres of elements near an extraordinary
    /// interior vertex or edge, in the refit of a pass that holds back more than a tenth of
    /// the elements (overrides the preset; 0: no refit).
    #[arg(long)]
    w_extraordinary_midpoint: Option<f64>,
    /// Position weight at midpoints of boundary edges and faces (overrides the preset).
    #[arg(long)]
    w_boundary_midpoint: Option<f64>,
    /// Frame (derivative) weight at corners (overrides the preset).
    #[arg(long)]
    w_frame_corner: Option<f64>,
    /// Frame weight at midpoints and centres (overrides the preset).
    #[arg(long)]
    w_frame_midpoint: Option<f64>,
    /// Position weight at samples on sharp features (overrides the preset: 100 with `--fit
    /// smooth`, 10 otherwise).
    #[arg(long)]
    w_feature: Option<f64>,
    #[command(flatten)]
    features: FeatureArgs,
    #[command(flatten)]
    periodic: PeriodicArgs,
    /// With `--fit smooth`: elements at vertices where a boundary grid line kinks (its
    /// turning within the surface jumps by more than the normal turning of the vertex's
    /// grid lines, at least 1° and at most this angle in degrees) become Q2 elements, which
    /// can follow the kink, as do those next to irregular boundary vertices; 180 turns
    /// this off.
    #[arg(long, default_value_t = 10.0, value_name = "DEG")]
    kink_angle: f64,
    /// With `--fit smooth`: where the fitted pass holds back more than a tenth of the
    /// elements, it is redone with the elements at regular interior vertices where an
    /// interior grid line turns by more than this angle in degrees made Q2, and the redo kept
    /// where it holds back fewer and keeps the boundary; 35 is the measured choice, 180 (the
    /// default) turns this off.
    #[arg(long, default_value_t = 180.0, value_name = "DEG")]
    interior_kink_angle: f64,
    /// After the fit, lower the map's kinks at C⁰ facets (where a Q2 element meets another
    /// element): W weighs the transversal-derivative jumps there against moving the interior
    /// control points from the fit (0: off). A move stands only where every element it
    /// shapes stays inside the blend's quality rules; the certificate and the blend still
    /// decide per element. Off by default: 0.015 brings the mean facet angle of the real
    /// meshes with many Q2 elements under 0.7× the straight elevation's, at up to 5× the CPU
    /// time (BENCHMARKS.md). Refused under mpirun. [default: 0]
    #[arg(long, value_name = "W")]
    facet_smoothing: Option<f64>,
    #[command(flatten)]
    knots: KnotArgs,
    /// Solver of the fit's normal equations: `auto` factors small systems (at most 12,000
    /// control points in 2D, 1,500 in 3D) by sparse Cholesky on the CPU backend and solves
    /// the rest by CG; `cg` and `cholesky` force one (distributed runs use CG: `auto` is CG
    /// there and `cholesky` is refused).
    #[arg(long, value_enum, default_value_t = FitSolver::default().into())]
    fit_solver: values::FitSolver,
    /// Relative tolerance of the conjugate-gradient solves (fit and elastic analogy)
    /// [default: 1e-6]. Under mpirun the ranks' CG takes the serial solve's iterates (the
    /// serial preconditioner) and stops where it stops, so no tighter tolerance is needed for
    /// the serial run's output (docs/distributed.md).
    #[arg(long, value_name = "CG_TOL")]
    cg_tol: Option<f64>,
    /// Preconditioner of the fit's CG solve on the CPU: the diagonal, exact inverses of the
    /// diagonal blocks on aggregates of 64 neighbouring control points (block Jacobi), or a
    /// symmetric Gauss–Seidel sweep over those blocks (block SGS, in Eisenstat's form: about
    /// 40 % of block Jacobi's iterations, each about 2.4 times as costly), or the average of
    /// block Jacobi on two staggered partitions (block Jacobi pair: about 60 % of block
    /// Jacobi's iterations, two block solves each; the default), or block Jacobi plus exact
    /// solves on the control points' lattice lines (block Jacobi lines). The GPU solver always
    /// uses the diagonal. Distributed runs apply the serial preconditioner (the serial run's
    /// aggregates, on any number of ranks); block SGS and block Jacobi lines are refused there.
    /// The fit across rotation seams couples the coordinates and runs one CG preconditioned by
    /// the block Jacobi pair (the diagonal on the GPU) whatever this says (the report's
    /// `coupled_fit_preconditioner`).
    #[arg(long, value_enum)]
    cg_preconditioner: Option<values::CgPreconditioner>,
    /// Most bisections of the validity line search.
    #[arg(long, default_value_t = 30)]
    max_bisections: usize,
    /// Move boundary vertex nodes back onto the input vertices where the result stays
    /// certified valid.
    #[arg(long)]
    snap_boundary: bool,
    /// Where the certified blend holds back elements and the initial spline map is not
    /// certified on some, fit again with those elements Q2 from the start and keep that output
    /// when it holds back fewer (under mpirun too: the ranks decide on the whole mesh). Without
    /// it this runs only where more than 10 % of the elements are held back, on meshes of at
    /// most 5,000 elements, and that output is kept only where its boundary stays as close to
    /// the first fit's as the first output's.
    #[arg(long)]
    demote_uncertified: bool,
    /// Accept an element in the line search only when its certified det J bound exceeds this
    /// fraction of its straight input element's smallest corner det J (0: any positive).
    #[arg(long, default_value_t = 0.1)]
    min_det_fraction: f64,
    /// Keep every element's Jacobian ratio (min/max det J) and scaled Jacobian at least this
    /// fraction of its straight-sided elevation's (0: no quality test).
    #[arg(long, default_value_t = 0.55)]
    min_quality_fraction: f64,
    /// Keep every element's Jacobian ratio and scaled Jacobian at least this fraction of
    /// min(its straight-sided elevation's, the straight mesh's 1st percentile).
    #[arg(long, default_value_t = 0.85)]
    percentile_quality_fraction: f64,
    /// Keep only the element rules (det J, the Jacobian ratio's and q_min × the straight
    /// scaled Jacobian): no scaled Jacobian floor of --percentile-quality-fraction × min(the
    /// straight element's, the straight mesh's 1st percentile).
    #[arg(long)]
    no_scaled_jacobian_floor: bool,
    /// Shorten the fitted step per control point around invalid elements (`local`), or by
    /// one factor for the whole mesh as in the paper (`global`).
    #[arg(long, value_enum, default_value_t = values::LineSearchMode::Local)]
    line_search: values::LineSearchMode,
    /// With --order 1: split each element into K^d linear elements on the curved geometry.
    #[arg(long, value_name = "K")]
    subdivide: Option<usize>,
    /// Keep tangled or degenerate input elements instead of failing.
    #[arg(long)]
    allow_invalid: bool,
    /// Where sampling, certification and the CG solve run: `auto` uses a hardware GPU
    /// when there is one and the CPU otherwise (a software adapter such as lavapipe only
    /// with `gpu`).
    #[arg(long, value_enum, default_value_t = values::BackendChoice::Auto)]
    backend: values::BackendChoice,
    /// Float type of the GPU kernels (default: f64 where the adapter has it).
    #[arg(long, value_enum)]
    precision: Option<values::Precision>,
    /// The options given (on the command line or as keywords), for [`JobArgs::resolve`]'s
    /// refusal of those this job cannot use.
    #[arg(skip)]
    given: Given,
}

/// How to write: the options of the output formats.
#[derive(clap::Args)]
pub(crate) struct OutputArgs {
    /// Gmsh file version.
    #[arg(long, value_enum, default_value_t = values::MshVersion::V41)]
    msh_version: values::MshVersion,
    /// Binary Gmsh output.
    #[arg(long)]
    binary: bool,
    /// How VTU data arrays are stored.
    #[arg(long, value_enum, default_value_t = values::VtuEncoding::Base64)]
    vtu_encoding: values::VtuEncoding,
    /// Name of the MSH volume physical group where the input names no region (PyFR reads
    /// its volume from a group named `fluid`).
    #[arg(long, default_value = "fluid", value_name = "NAME")]
    volume_name: String,
    /// Also write the boundary facets, with their tags, to this VTU file (the main VTU
    /// holds the volume cells only).
    #[arg(long, value_name = "FILE.vtu")]
    pub(crate) vtu_boundary: Option<PathBuf>,
    /// The options given, for [`OutputArgs::refuse_inapplicable`].
    #[arg(skip)]
    given: Given,
}

impl OutputArgs {
    /// Record which options `matches` (this group's parse) holds from the command line.
    pub(crate) fn record_given(&mut self, matches: &clap::ArgMatches) {
        self.given = Given::of(matches);
    }

    /// Refuse the writers' options given for an output format that does not use them.
    pub(crate) fn refuse_inapplicable(&self, format: OutputFormat) -> anyhow::Result<()> {
        let name = match format {
            OutputFormat::Msh => "Gmsh MSH",
            OutputFormat::Vtu => "VTU",
            OutputFormat::Cgns => "CGNS",
            OutputFormat::Inp => "Abaqus",
        };
        let msh = format!("the output is {name}, not Gmsh MSH");
        self.given.refuse(&[
            Rule::new(
                &["msh_version", "binary"],
                format == OutputFormat::Msh,
                &msh,
            ),
            Rule::new(
                &["vtu_encoding"],
                format == OutputFormat::Vtu || self.vtu_boundary.is_some(),
                &format!("the output is {name}, not VTU, and no --vtu-boundary is written"),
            ),
            Rule::new(
                &["volume_name"],
                format != OutputFormat::Vtu,
                "VTU cells carry no group names",
            ),
        ])
    }

    /// The library's output options (unchecked: the writers validate them).
    pub(crate) fn options(self) -> OutputOptions {
        OutputOptions {
            msh_version: self.msh_version.into(),
            binary: self.binary,
            vtu_encoding: self.vtu_encoding.into(),
            volume_name: self.volume_name,
            vtu_boundary: self.vtu_boundary,
        }
    }
}

/// Options of `--fit energy`.
#[derive(clap::Args)]
struct EnergyArgs {
    /// Minimiser of the degeneration energy: global L-BFGS, or coloured local Newton steps.
    #[arg(long, value_enum, default_value_t = values::EnergySolver::Lbfgs)]
    energy_solver: values::EnergySolver,
    /// Weight of the degeneration energy against the least-squares terms.
    #[arg(long, default_value_t = EnergyParams::default().weight)]
    energy_weight: f64,
    /// L-BFGS iterations or coloured sweeps at most.
    #[arg(long, default_value_t = EnergyParams::default().max_iterations)]
    energy_max_iterations: usize,
    /// Stop L-BFGS when an iteration lowers the energy by less than this fraction.
    #[arg(long, default_value_t = EnergyParams::default().rel_tol)]
    energy_tol: f64,
    /// Stop the coloured solver when a sweep lowers the energy by less than this fraction.
    #[arg(long, default_value_t = EnergyParams::default().sweep_tol)]
    energy_sweep_tol: f64,
}

impl EnergyArgs {
    fn params(&self) -> EnergyParams {
        EnergyParams {
            weight: self.energy_weight,
            solver: self.energy_solver.into(),
            max_iterations: self.energy_max_iterations,
            rel_tol: self.energy_tol,
            sweep_tol: self.energy_sweep_tol,
            ..Default::default()
        }
    }
}

impl JobArgs {
    /// The library's options with the output options `output`, after the checks the library
    /// leaves to its caller: the kink angle, and the backend (resolved here: `gpu` without
    /// an adapter is an error).
    pub(crate) fn resolve(self, output: OutputOptions) -> anyhow::Result<CurveOptions> {
        polyspline::fit::check_kink_angle(self.kink_angle)?;
        polyspline::fit::check_interior_kink_angle(self.interior_kink_angle)?;
        if let Some(w) = self.facet_smoothing
            && !(w.is_finite() && w >= 0.0)
        {
            anyhow::bail!("--facet-smoothing {w}: must be a finite weight of at least 0");
        }
        let backend = BackendChoice::from(self.backend).resolve(self.precision.map(Into::into))?;
        self.refuse_inapplicable(backend.gpu().is_some())?;
        Ok(self.options(backend, output))
    }

    /// Record which options `matches` (this group's parse) holds from the command line.
    pub(crate) fn record_given(&mut self, matches: &clap::ArgMatches) {
        self.given = Given::of(matches);
    }

    /// Refuse the options given that this job cannot use (`gpu`: it runs on a GPU), naming
    /// them and why, instead of ignoring them. One rule per group of options: the job uses
    /// them exactly when the rule's condition holds.
    fn refuse_inapplicable(&self, gpu: bool) -> anyhow::Result<()> {
        use values::{ElasticSolver as Es, EnergySolver as En, FitPreset as Fp, FitSolver as Fs};
        let elastic = self.method == values::Method::Elastic;
        let spline = !self.straight;
        let fitted = spline && self.fit != Fp::None;
        let no_fit = if self.straight {
            "--straight writes the straight-sided elevation: no spline, fit or line search"
        } else {
            "--fit none samples the initial spline: nothing is fitted"
        };
        let fit_cg = fitted && self.fit_solver != Fs::Cholesky;
        let elastic_cg = elastic && self.elastic.solver() != Es::Cholesky;
        let no_cg = if !fitted && !elastic {
            no_fit
        } else {
            "no CG solve runs: --fit-solver cholesky, without --method elastic solved by CG"
        };
        let preconditioner = if !fit_cg {
            no_cg
        } else {
            "the GPU backend's CG uses the diagonal, jacobi"
        };
        let energy = self.fit == Fp::Energy;
        let energy_solver = self.energy.energy_solver;
        self.given.refuse(&[
            Rule::new(
                &[
                    "w_corner",
                    "w_boundary_corner",
                    "w_midpoint",
                    "w_deep_midpoint",
                    "w_extraordinary_midpoint",
                    "w_boundary_midpoint",
                    "w_frame_corner",
                    "w_frame_midpoint",
                    "w_feature",
                    "fit_solver",
                    "facet_smoothing",
                ],
                fitted,
                no_fit,
            ),
            Rule::new(&["cg_tol"], fit_cg || elastic_cg, no_cg),
            Rule::new(
                &["cg_preconditioner"],
                fit_cg
                    && (!gpu || self.cg_preconditioner == Some(values::CgPreconditioner::Jacobi)),
                preconditioner,
            ),
            Rule::new(
                &["kink_angle", "interior_kink_angle"],
                fitted && FitPreset::from(self.fit).smooth_targets(),
                if fitted {
                    "kinks are found for the targets of --fit smooth and --fit energy only"
                } else {
                    no_fit
                },
            ),
            Rule::new(
                &[
                    "knot_intervals",
                    "feature_angle",
                    "no_feature_tags",
                    "feature_edits",
                    "ignore_features",
                    "max_bisections",
                    "min_det_fraction",
                    "min_quality_fraction",
                    "percentile_quality_fraction",
                    "no_scaled_jacobian_floor",
                    "line_search",
                    "snap_boundary",
                ],
                spline,
                no_fit,
            ),
            Rule::new(
                &["knot_max_ratio", "knot_max_spread"],
                spline && !self.knots.uniform(),
                if spline {
                    "--knot-intervals uniform grades no interval"
                } else {
                    no_fit
                },
            ),
            // The rule redoes the least-squares spline pass (`--fit energy` demotes
            // uncertified elements itself).
            Rule::new(
                &["demote_uncertified"],
                fitted && !elastic && !energy,
                "the demotion redoes the least-squares spline fit: not with --straight, \
                 --method elastic, --fit none or --fit energy (which demotes uncertified \
                 elements itself)",
            ),
            Rule::new(
                &[
                    "young",
                    "poisson",
                    "elastic_solver",
                    "elastic_stiffening",
                ],
                elastic,
                "the elastic analogy runs with --method elastic only",
            ),
            Rule::new(
                &["elastic_preconditioner"],
                elastic_cg,
                "the elastic analogy's CG runs with --method elastic and an --elastic-solver other than cholesky",
            ),
            Rule::new(
                &["energy_solver", "energy_weight", "energy_max_iterations"],
                energy,
                "the energy minimiser runs with --fit energy only",
            ),
            Rule::new(
                &["energy_tol"],
                energy && energy_solver == En::Lbfgs,
                "L-BFGS runs with --fit energy and --energy-solver lbfgs only",
            ),
            Rule::new(
                &["energy_sweep_tol"],
                energy && energy_solver == En::Colored,
                "coloured sweeps run with --fit energy and --energy-solver colored only",
            ),
            Rule::new(
                &["precision"],
                gpu,
                "the job runs on the CPU: --backend cpu, or --backend auto without a hardware GPU",
            ),
        ])
    }

    /// The preset's weights with the single weights given on the command line.
    fn weights(&self) -> FitWeights {
        let mut weights = FitPreset::from(self.fit).weights();
        for (slot, value) in [
            (&mut weights.corner, self.w_corner),
            (&mut weights.boundary_corner, self.w_boundary_corner),
            (&mut weights.midpoint, self.w_midpoint),
            (
                &mut weights.extraordinary_midpoint,
                self.w_extraordinary_midpoint,
            ),
            (&mut weights.boundary_midpoint, self.w_boundary_midpoint),
            (&mut weights.frame_corner, self.w_frame_corner),
            (&mut weights.frame_midpoint, self.w_frame_midpoint),
            (&mut weights.feature, self.w_feature),
        ] {
            if let Some(v) = value {
                *slot = v;
            }
        }
        weights.deep_midpoint = self.w_deep_midpoint;
        weights
    }

    /// The library's options (unchecked: [`curve_prepared`] validates them).
    fn options(
        self,
        backend: polyspline::exec::gpu::Backend,
        output: OutputOptions,
    ) -> CurveOptions {
        CurveOptions {
            order: self.order,
            subdivide: self.subdivide,
            geometry: if self.straight {
                Geometry::Straight
            } else if self.fit == values::FitPreset::None {
                Geometry::SplineInitial
            } else {
                Geometry::SplineFitted
            },
            method: match self.method {
                values::Method::Elastic => Method::Elastic(self.elastic.params(self.cg_tol)),
                values::Method::Iga => Method::Iga,
            },
            fit: FitParams {
                weights: self.weights(),
                solver: self.fit_solver.into(),
                cg: CgParams {
                    rel_tol: self.cg_tol.unwrap_or(FIT_CG_TOL),
                    preconditioner: self
                        .cg_preconditioner
                        .map_or_else(CgPreconditioner::default, Into::into),
                    ..Default::default()
                },
                targets: if FitPreset::from(self.fit).smooth_targets() {
                    FitTargets::Smooth(SmoothParams {
                        kink_angle_deg: self.kink_angle,
                        interior_kink_angle_deg: self.interior_kink_angle,
                        ..Default::default()
                    })
                } else {
                    FitTargets::Chords
                },
                facet_smoothing: self.facet_smoothing.unwrap_or(0.0),
                ..Default::default()
            },
            knots: self.knots.params(),
            features: self.features.options(),
            line_search: LineSearchParams {
                max_bisections: self.max_bisections,
                min_det_fraction: self.min_det_fraction,
                min_quality_fraction: self.min_quality_fraction,
                percentile_quality_fraction: self.percentile_quality_fraction,
                scaled_jacobian_floor: !self.no_scaled_jacobian_floor,
                ..Default::default()
            },
            snap_boundary: self.snap_boundary,
            demote_uncertified: self.demote_uncertified,
            line_search_mode: self.line_search.into(),
            mesh: MeshOptions {
                allow_invalid: self.allow_invalid,
            },
            output,
            backend,
            energy: (self.fit == values::FitPreset::Energy).then(|| self.energy.params()),
            periodic: self.periodic.options(),
        }
    }
}

pub(super) fn run(args: Args) -> anyhow::Result<()> {
    let job = prepare_files(args.files)?;
    // Under mpirun with several ranks: the distributed job (docs/distributed.md).
    #[cfg(feature = "mpi")]
    if polyspline::distributed::launch::distributed() {
        use super::launch::curve;
        use polyspline::distributed::launch::Outcome;
        let Prepared {
            mesh,
            output,
            report,
            edits,
            partitioned,
            parts,
            options,
        } = &job;
        let mut inputs: Vec<&Path> = vec![mesh];
        inputs.extend(edits.as_deref());
        let written = curve(
            mesh,
            output,
            options,
            report.as_deref(),
            &inputs,
            *partitioned,
        )?;
        if let Outcome::Written(r) = written {
            let what = if *partitioned {
                format!(
                    "{} … {}",
                    parts[0].display(),
                    parts[parts.len() - 1].display()
                )
            } else {
                output.display().to_string()
            };
            eprintln!(
                "wrote {what}: {} elements of order {}, {} nodes, {} boundary facets, on {} ranks ({:.3} s)",
                r.output_elements,
                r.order,
                r.output_nodes,
                r.boundary_facets,
                r.ranks.unwrap_or(1),
                r.timings["total"]
            );
        }
        return Ok(());
    }
    let progress = polyspline::progress::Terminal::new(args.quiet);
    let r = curve_files(&job, &progress);
    progress.clear();
    print_summary(&r?);
    Ok(())
}

/// The options given on the command line or as keyword arguments (clap ids), as opposed to
/// those left at their defaults: an option given where the job cannot use it is refused.
#[derive(Clone, Debug, Default)]
pub(crate) struct Given(Vec<String>);

impl Given {
    /// The arguments of `matches` whose value came from the command line.
    fn of(matches: &clap::ArgMatches) -> Given {
        use clap::parser::ValueSource;
        Given(
            matches
                .ids()
                .filter(|id| matches.value_source(id.as_str()) == Some(ValueSource::CommandLine))
                .map(|id| id.as_str().to_owned())
                .collect(),
        )
    }

    /// The first rule whose options were given though the job does not use them, as one line
    /// naming them and why.
    fn refuse(&self, rules: &[Rule]) -> anyhow::Result<()> {
        for rule in rules.iter().filter(|r| !r.applies) {
            let given: Vec<String> = rule
                .options
                .iter()
                .filter(|id| self.0.iter().any(|g| g == *id))
                .map(|id| format!("--{}", id.replace('_', "-")))
                .collect();
            if !given.is_empty() {
                let (verb, pronoun) = match given.len() {
                    1 => ("does", "it"),
                    _ => ("do", "them"),
                };
                // An options error, as the library's own refusals (Python: ParameterError).
                return Err(CurveError::Options(format!(
                    "{} {verb} not apply to this job ({}); drop {pronoun}",
                    given.join(", "),
                    rule.why
                ))
                .into());
            }
        }
        Ok(())
    }
}

/// Options (clap ids), whether the job uses them, and why not when it does not.
struct Rule<'a> {
    options: &'a [&'a str],
    applies: bool,
    why: &'a str,
}

impl<'a> Rule<'a> {
    fn new(options: &'a [&'a str], applies: bool, why: &'a str) -> Self {
        Rule {
            options,
            applies,
            why,
        }
    }
}

/// A `curve` job whose options and outputs passed every check that needs no work.
pub(crate) struct Prepared {
    mesh: PathBuf,
    output: PathBuf,
    report: Option<PathBuf>,
    /// The feature edits file, another input no output may replace.
    edits: Option<PathBuf>,
    #[cfg_attr(not(feature = "mpi"), allow(dead_code))]
    partitioned: bool,
    /// The mesh files to write: `output`, or the parts of `--partitioned`.
    #[cfg_attr(not(feature = "mpi"), allow(dead_code))]
    parts: Vec<PathBuf>,
    pub(crate) options: CurveOptions,
}

/// Refuse, before any work, what no run could write: an output of no known format or of an
/// order its format cannot hold, outputs onto the inputs or each other, the checks
/// [`JobArgs::resolve`] makes, and a backend that cannot start.
pub(crate) fn prepare_files(args: FileArgs) -> anyhow::Result<Prepared> {
    let FileArgs {
        mesh,
        output,
        report,
        partitioned,
        job,
        out,
    } = args;
    let edits = job.features.feature_edits.clone();
    let prechecks = || -> anyhow::Result<_> {
        let parts = partitioned_outputs(&output, partitioned)?;
        let Some(format) = OutputFormat::from_path(&output) else {
            anyhow::bail!(
                "{}: {}",
                output.display(),
                polyspline::io::high_order::UNKNOWN_OUTPUT
            );
        };
        // An order the format cannot hold is refused before any work (the dimension is
        // known only after reading; 3 is the stricter for Gmsh).
        if let Some(why) = [2, 3]
            .iter()
            .filter_map(|&d| format.refuses(d, job.order))
            .next()
            .filter(|_| format != OutputFormat::Msh)
        {
            anyhow::bail!("{}: {why}", output.display());
        }
        // Every output path is checked against the inputs and each other.
        let mut inputs: Vec<&Path> = vec![&mesh];
        inputs.extend(edits.as_deref());
        let outputs: Vec<&Path> = parts
            .iter()
            .map(PathBuf::as_path)
            .chain(report.as_deref())
            .collect();
        check_outputs(&outputs, &inputs)?;
        out.refuse_inapplicable(format)?;
        Ok(parts)
    };
    // Under mpirun every rank finds the same error: one line, from rank 0.
    #[cfg(feature = "mpi")]
    let prechecks = || prechecks().map_err(super::launch::quiet_unless_rank_0);
    let parts = prechecks()?;
    let options = job.resolve(out.options());
    #[cfg(feature = "mpi")]
    let options = options.map_err(super::launch::quiet_unless_rank_0);
    Ok(Prepared {
        options: options?,
        mesh,
        output,
        report,
        edits,
        partitioned,
        parts,
    })
}

/// Run a prepared job on this process, reporting to `progress`: the mesh and the report are
/// both complete on disk before either replaces its target, so a full disk or a failing
/// report leaves no mesh without its report.
pub(crate) fn curve_files(job: &Prepared, progress: &dyn Progress) -> anyhow::Result<CurveReport> {
    refuse_a_single_part(&job.mesh)?;
    let mut inputs: Vec<&Path> = vec![&job.mesh];
    inputs.extend(job.edits.as_deref());
    let (r, pending_mesh) = curve_prepared(&job.mesh, &job.output, &job.options, progress)?;
    let pending_report = match &job.report {
        Some(path) => {
            let json = serde_json::to_string_pretty(&r)?;
            Some(prepare(path, &inputs, |w| {
                use std::io::Write;
                writeln!(w, "{json}")
            })?)
        }
        None => None,
    };
    pending_mesh.commit()?;
    if let Some(p) = pending_report {
        p.commit()?;
    }
    Ok(r)
}

/// The output files: `OUTPUT`, or with `--partitioned` Gmsh's part names `OUT_1 … OUT_N` for
/// the N ranks of the MPI job (which must have more than one rank).
fn partitioned_outputs(output: &Path, partitioned: bool) -> anyhow::Result<Vec<PathBuf>> {
    if !partitioned {
        return Ok(vec![output.to_owned()]);
    }
    #[cfg(feature = "mpi")]
    if polyspline::distributed::launch::distributed() {
        let n = polyspline::distributed::launch::launched_size().unwrap_or(1);
        return Ok(polyspline::distributed::write_parts::part_paths(output, n));
    }
    anyhow::bail!(
        "{}: --partitioned writes one file per MPI rank and needs mpirun with 2 or more ranks (a build with --features mpi); on one process, drop it to write one file",
        output.display()
    )
}

/// One of Gmsh's split partition files (`NAME_k.msh` with `$PartitionedEntities`) on one
/// process would be curved alone, as if it were the whole mesh, its cut faces taken for
/// boundary: refused with one line.
fn refuse_a_single_part(mesh: &Path) -> anyhow::Result<()> {
    use polyspline::distributed::part_file::{is_partitioned, part_names};
    let numbered = mesh
        .file_stem()
        .and_then(|s| s.to_str())
        .and_then(|s| s.rsplit_once('_'))
        .is_some_and(|(_, k)| !k.is_empty() && k.bytes().all(|c| c.is_ascii_digit()));
    if !numbered || !is_partitioned(mesh) {
        return Ok(());
    }
    let set = match part_names(mesh) {
        Ok((parts, _)) if parts.len() < 2 => return Ok(()),
        Ok((parts, _)) => format!(
            "one of the {} parts {} … {} of a partitioned mesh",
            parts.len(),
            parts[0].display(),
            parts[parts.len() - 1].display()
        ),
        Err(e) => format!("a part of a partitioned mesh ({})", e.message),
    };
    anyhow::bail!(
        "{}: {set}; curve the parts together under mpirun with 2 or more ranks (a build with --features mpi), or curve the unpartitioned mesh",
        mesh.display()
    )
}

/// The lines on stderr after a successful run (the JSON report holds the same figures).
fn print_summary(r: &CurveReport) {
    eprintln!(
        "wrote {}: {} elements of order {}, {} nodes, {} boundary facets ({:.3} s)",
        r.output.display(),
        r.output_elements,
        r.order,
        r.output_nodes,
        r.boundary_facets,
        r.timings["total"]
    );
    if r.control_points > 0 {
        eprintln!(
            "spline: {} control points, {} spline and {} Q2 elements ({} at boundary kinks)",
            r.control_points, r.spline_elements, r.q2_elements, r.kink_elements
        );
    }
    if let (Some(it), Some(res), Some(alpha)) =
        (r.cg_iterations, r.cg_rel_residual, r.line_search_alpha)
    {
        let solve = if r.fit_solver == Some(FitSolver::Cholesky) {
            "sparse Cholesky".to_string()
        } else {
            format!("{it} CG iterations")
        };
        eprintln!(
            "fit: {solve}, relative residual {res:.2e}; {} elements invalid at the full step, {} control points damped, smallest step {alpha:.4}",
            r.invalid_at_full_step, r.damped_control_points
        );
    }
    if let (Some(device), Some(pre)) = (r.coupled_fit_device, r.coupled_fit_preconditioner) {
        eprintln!(
            "fit: coupled across rotation seams, CG on {device} preconditioned by K's {pre} (--cg-preconditioner sets the uncoupled fit's only)"
        );
    }
    if let Some(e) = &r.energy {
        eprintln!(
            "energy: {:?}, {} {} ({:?}), Q {:.4e} -> {:.4e}, degeneration {:.4e} -> {:.4e}",
            e.solver,
            e.iterations,
            if e.solver == EnergySolver::Colored {
                "sweeps"
            } else {
                "iterations"
            },
            e.stop,
            e.initial_energy,
            e.final_energy,
            e.initial_degeneration,
            e.final_degeneration
        );
    }
    if let Some(e) = &r.elastic {
        let solve = match e.solver {
            ElasticSolver::Cholesky => {
                format!("sparse Cholesky ({} factor entries)", e.factor_entries)
            }
            _ => format!("{} CG iterations ({:?})", e.cg.iterations, e.preconditioner),
        };
        eprintln!(
            "elastic: E {} nu {}, {} unknowns, {solve}, relative residual {:.2e}",
            e.young, e.poisson, e.unknowns, e.cg.rel_residual
        );
        if e.held_back_nodes > 0 {
            eprintln!(
                "elastic: {} nodes ({} on the boundary) moved back towards the straight mesh to keep every element valid (smallest kept share of the displacement {:.3})",
                e.held_back_nodes, e.held_back_boundary_nodes, e.min_displacement_fraction
            );
        }
    }
    if let Some(n) = r.snapped_boundary_vertices {
        eprintln!(
            "snap: {n} boundary vertex nodes moved onto the input vertices (edge and face nodes stay)"
        );
    }
    eprintln!(
        "quality: min scaled Jacobian {:.4} (input {:.4}), invalid elements {}",
        r.min_scaled_jacobian, r.input_min_scaled_jacobian, r.invalid_elements,
    );
    eprintln!(
        "boundary (relative to the diagonal {:.4e}): vertex nodes from the input vertices max {:.2e} rms {:.2e}; every boundary node from the input's linear boundary max {:.2e}, sampled facets max {:.2e}",
        r.bounding_box_diagonal,
        r.boundary_vertex_deviation_max,
        r.boundary_vertex_deviation_rms,
        r.boundary_node_distance_max,
        r.boundary_sample_distance_max
    );
}
