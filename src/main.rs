//! The `polyspline` command line.

use clap::{Parser, Subcommand};
use polyspline::compare::{CompareOptions, compare};
use polyspline::elastic::{ElasticParams, ElasticPreconditioner};
use polyspline::energy::{EnergyParams, EnergySolver};
use polyspline::fit::{FitParams, FitTargets, FitWeights, SmoothParams};
use polyspline::info::MeshInfo;
use polyspline::io::gmsh_write::MshVersion;
use polyspline::io::output::{check_outputs, prepare, write_atomically};
use polyspline::io::vtu_write::VtuEncoding;
use polyspline::io::{read_mesh, read_raw};
use polyspline::mesh::{MeshOptions, Topology};
use polyspline::pipeline::{
    CurveOptions, Geometry, LineSearchMode, Method, OutputFormat, OutputOptions, curve_prepared,
};
use polyspline::plot::{Layer, render_svg_window};
use polyspline::quality::CheckReport;
use polyspline::sample::HighOrderMesh;
use polyspline::solve::CgParams;
use polyspline::validity::LineSearchParams;
use std::path::{Path, PathBuf};
use std::process::ExitCode;

#[derive(Parser)]
#[command(
    name = "polyspline",
    version,
    about = "Curved high-order quad/hex meshes from linear ones, without CAD"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

// Parsed once per run: the size of the largest variant (`curve`'s options) does not matter.
#[allow(clippy::large_enum_variant)]
#[derive(Subcommand)]
enum Command {
    /// Read a linear quad/hex mesh and report its size, topology and quality.
    Info {
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
    },
    /// Make a curved high-order mesh from a linear quad/hex mesh.
    Curve {
        /// Input mesh file.
        mesh: PathBuf,
        /// Output file: .msh (Gmsh) or .vtu (VTK Lagrange cells).
        #[arg(short, long)]
        output: PathBuf,
        /// No progress spinner on stderr (it is also off when stderr is not a terminal).
        #[arg(short, long)]
        quiet: bool,
        /// Order of the output elements (1-10; Gmsh hexes up to 9).
        #[arg(long, default_value_t = 2)]
        order: usize,
        /// Write the straight-sided order-P mesh of the input (no curving), for comparison.
        #[arg(long, conflicts_with_all = ["fit", "method"])]
        straight: bool,
        /// `iga` samples the fitted spline everywhere; `elastic` (the paper's baseline, §2.5)
        /// puts the boundary nodes on the same fitted spline and moves the interior nodes of the
        /// straight order-P mesh by linear elasticity.
        #[arg(long, value_enum, default_value_t = MethodArg::Iga)]
        method: MethodArg,
        #[command(flatten)]
        elastic: ElasticArgs,
        /// Fit of the spline control points: `none` samples the initial spline map; `position`
        /// and `frame` are the paper's weight presets (least squares, then a certified line
        /// search); `smooth` takes the midpoint targets from a local reconstruction of the
        /// smooth boundary instead of the straight chords (more accurate curved boundaries; the
        /// default); `energy` is `smooth` followed by minimising the element degeneration energy
        /// under the det J certificate (paper §2.4, docs/energy.md).
        #[arg(long, value_enum, default_value_t = FitArg::Smooth)]
        fit: FitArg,
        #[command(flatten)]
        energy: EnergyArgs,
        /// Position weight at interior element corners (overrides the preset).
        #[arg(long)]
        w_corner: Option<f64>,
        /// Position weight at element corners on the boundary (overrides the preset).
        #[arg(long)]
        w_boundary_corner: Option<f64>,
        /// Position weight at edge/face midpoints and element centres (overrides the preset).
        #[arg(long)]
        w_midpoint: Option<f64>,
        /// Frame (derivative) weight at corners (overrides the preset).
        #[arg(long)]
        w_frame_corner: Option<f64>,
        /// Frame weight at midpoints and centres (overrides the preset).
        #[arg(long)]
        w_frame_midpoint: Option<f64>,
        /// Position weight at element corners on sharp-feature vertices (default 10).
        #[arg(long)]
        w_feature: Option<f64>,
        #[command(flatten)]
        features: FeatureArgs,
        /// With `--fit smooth`: elements at vertices where a boundary grid line kinks (its
        /// turning within the surface jumps by more than the normal turning of the vertex's
        /// grid lines, at least 1° and at most this angle in degrees) become Q2 elements, which
        /// can follow the kink, as do those next to irregular boundary vertices; 180 turns
        /// this off.
        #[arg(long, default_value_t = 10.0, value_name = "DEG")]
        kink_angle: f64,
        /// Relative tolerance of the conjugate-gradient solve.
        #[arg(long, default_value_t = 1e-6)]
        cg_tol: f64,
        /// Preconditioner of the fit's CG solve on the CPU: the diagonal, or exact inverses of
        /// the diagonal blocks on aggregates of 64 neighbouring control points (the GPU solver
        /// always uses the diagonal).
        #[arg(long, value_enum, default_value_t = FitPreconditionerArg::BlockJacobi)]
        cg_preconditioner: FitPreconditionerArg,
        /// Most bisections of the validity line search.
        #[arg(long, default_value_t = 30)]
        max_bisections: usize,
        /// Move boundary vertex nodes back onto the input vertices where the result stays
        /// certified valid.
        #[arg(long)]
        snap_boundary: bool,
        /// Accept an element in the line search only when its certified det J bound exceeds this
        /// fraction of its straight input element's smallest corner det J (0: any positive).
        #[arg(long, default_value_t = 0.1)]
        min_det_fraction: f64,
        /// Keep every element's Jacobian ratio (min/max det J) and scaled Jacobian at least this
        /// fraction of its straight-sided elevation's (0: no quality test).
        #[arg(long, default_value_t = 0.55)]
        min_quality_fraction: f64,
        /// Keep every element's Jacobian ratio at least this fraction of min(its straight ratio,
        /// the straight mesh's 1st percentile).
        #[arg(long, default_value_t = 0.85)]
        percentile_quality_fraction: f64,
        /// Shorten the fitted step per control point around invalid elements (`local`), or by
        /// one factor for the whole mesh as in the paper (`global`).
        #[arg(long, value_enum, default_value_t = LineSearchArg::Local)]
        line_search: LineSearchArg,
        /// With --order 1: split each element into K^d linear elements on the curved geometry.
        #[arg(long, value_name = "K")]
        subdivide: Option<usize>,
        /// Gmsh file version.
        #[arg(long, value_enum, default_value_t = MshVersionArg::V41)]
        msh_version: MshVersionArg,
        /// Binary Gmsh output.
        #[arg(long)]
        binary: bool,
        /// How VTU data arrays are stored.
        #[arg(long, value_enum, default_value_t = VtuEncodingArg::Base64)]
        vtu_encoding: VtuEncodingArg,
        /// Name of the MSH volume physical group where the input names no region (PyFR reads
        /// its volume from a group named `fluid`).
        #[arg(long, default_value = "fluid", value_name = "NAME")]
        volume_name: String,
        /// Also write the boundary facets, with their tags, to this VTU file (the main VTU
        /// holds the volume cells only).
        #[arg(long, value_name = "FILE.vtu")]
        vtu_boundary: Option<PathBuf>,
        /// Write a JSON report (sizes, timings) to this file.
        #[arg(long, value_name = "FILE.json")]
        report: Option<PathBuf>,
        /// Keep tangled or degenerate input elements instead of failing.
        #[arg(long)]
        allow_invalid: bool,
        /// Where sampling, certification and the CG solve run: `auto` uses a hardware GPU
        /// when there is one and the CPU otherwise (a software adapter such as lavapipe only
        /// with `gpu`).
        #[arg(long, value_enum, default_value_t = BackendArg::Auto)]
        backend: BackendArg,
        /// Float type of the GPU kernels (default: f64 where the adapter has it).
        #[arg(long, value_enum)]
        precision: Option<PrecisionArg>,
    },
    /// Curve one mesh with every method (straight, IGA with the position, frame and smooth
    /// fits, elastic analogy) and print one table: times, validity, quality, boundary
    /// deviation and the facet angle jump (docs/compare.md). Writes nothing.
    Compare {
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
        /// Relative tolerance of the conjugate-gradient solves (fit and elasticity).
        #[arg(long, default_value_t = 1e-6)]
        cg_tol: f64,
        /// Keep tangled or degenerate input elements instead of failing.
        #[arg(long)]
        allow_invalid: bool,
        /// Where sampling, certification and the fit's CG solve run (the elastic solve runs on
        /// the CPU).
        #[arg(long, value_enum, default_value_t = BackendArg::Cpu)]
        backend: BackendArg,
        #[command(flatten)]
        features: FeatureArgs,
    },
    /// Make a synthetic linear mesh with curved boundaries for benchmarks: a butterfly disc
    /// (2D), a solid cylinder or a torus (3D), with valence-3 vertices/edges; or a
    /// boundary-layer O-grid (ellipse, circle, NACA 00xx) or C-grid (NACA 00xx with a wake cut).
    Generate {
        #[arg(value_enum)]
        kind: KindArg,
        /// Approximate number of elements (disc, cylinder, torus).
        #[arg(long, required_if_eq_any([("kind", "disc"), ("kind", "cylinder"), ("kind", "torus")]))]
        elements: Option<usize>,
        /// Output file (.msh or .vtu).
        #[arg(short, long)]
        output: PathBuf,
        /// Binary Gmsh output.
        #[arg(long)]
        binary: bool,
        #[command(flatten)]
        layer: BoundaryLayerArgs,
    },
    /// Report the validity and quality of a high-order mesh (.msh or .vtu).
    Check {
        /// High-order mesh file.
        mesh: PathBuf,
        /// Print one JSON object instead of a table.
        #[arg(long)]
        json: bool,
    },
    /// Draw a 2D mesh (linear or high order) as SVG, with curved edges drawn as curves.
    Plot {
        /// Mesh file (.msh, .vtu, or any input format).
        mesh: PathBuf,
        /// Output SVG file.
        #[arg(short, long)]
        output: PathBuf,
        /// Draw another mesh on top, in its own colour (e.g. the linear input, or a second
        /// method's result: IGA vs elastic as in the paper's Fig. 2f). Repeatable.
        #[arg(long, value_name = "MESH")]
        overlay: Vec<PathBuf>,
        /// Legend labels: the first for MESH, then one per --overlay (default: file names).
        #[arg(long, value_name = "NAME")]
        label: Vec<String>,
        /// Also draw every mesh's nodes (high-order nodes included) as dots in its colour.
        #[arg(long)]
        nodes: bool,
        /// Show only this rectangle of the plane (a zoom): X0,Y0,X1,Y1.
        #[arg(long, value_name = "X0,Y0,X1,Y1", allow_hyphen_values = true)]
        window: Option<String>,
        /// Picture width in pixels.
        #[arg(long, default_value_t = 1000.0)]
        width: f64,
        /// MESH is a linear input: also draw its poly-spline control points and the unfitted
        /// spline map they define (paper Fig. 1).
        #[arg(long)]
        control_points: bool,
        /// MESH is a linear input: also mark its sharp features (2D: corners of the boundary
        /// polygon), found with the --feature-* options.
        #[arg(long)]
        show_features: bool,
        #[command(flatten)]
        features: FeatureArgs,
    },
}

#[derive(Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
enum MethodArg {
    Iga,
    Elastic,
}

/// Preconditioner of the fit's CG solve.
#[derive(Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
enum FitPreconditionerArg {
    Jacobi,
    BlockJacobi,
}

impl From<FitPreconditionerArg> for polyspline::solve::CgPreconditioner {
    fn from(a: FitPreconditionerArg) -> Self {
        match a {
            FitPreconditionerArg::Jacobi => Self::Jacobi,
            FitPreconditionerArg::BlockJacobi => Self::default(),
        }
    }
}

#[derive(Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
enum PreconditionerArg {
    Jacobi,
    BlockJacobi,
    BlockSgs,
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
    #[arg(long, value_enum, default_value_t = PreconditionerArg::BlockJacobi)]
    elastic_preconditioner: PreconditionerArg,
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
            preconditioner: match self.elastic_preconditioner {
                PreconditionerArg::Jacobi => ElasticPreconditioner::Jacobi,
                PreconditionerArg::BlockJacobi => ElasticPreconditioner::BlockJacobi,
                PreconditionerArg::BlockSgs => ElasticPreconditioner::BlockSgs,
            },
        }
    }
}

#[derive(Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
enum KindArg {
    Disc,
    Cylinder,
    Torus,
    /// Boundary-layer O-grid around `--wall`.
    Ogrid,
    /// Boundary-layer C-grid around a NACA 00xx airfoil with a wake cut.
    Cgrid,
}

#[derive(Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
enum WallArg {
    /// Semi-axes 1 and `--thickness` (chord 2).
    Ellipse,
    /// Radius 1 (chord 2).
    Circle,
    /// NACA 00xx of chord 1, thickness `--thickness`, closed trailing edge.
    Naca,
}

/// Options of `generate ogrid|cgrid` (lengths in wall units: chord 2 for the ellipse and
/// the circle, 1 for the airfoil).
#[derive(clap::Args)]
struct BoundaryLayerArgs {
    /// Wall curve [default: ellipse for ogrid, naca for cgrid].
    #[arg(long, value_enum)]
    wall: Option<WallArg>,
    /// Ellipse: minor/major semi-axis ratio (default 0.2); airfoil: maximum thickness over
    /// chord (default 0.12).
    #[arg(long)]
    thickness: Option<f64>,
    /// Cells around the wall (even for the airfoil).
    #[arg(long, default_value_t = 128)]
    around: usize,
    /// Cells from the wall to the far field.
    #[arg(long, default_value_t = 48)]
    across: usize,
    /// Height of the first cell off the wall (absolute).
    #[arg(long, default_value_t = 1e-5)]
    first_height: f64,
    /// Wall-normal growth ratio of the cell heights near the wall.
    #[arg(long, default_value_t = 1.25)]
    growth: f64,
    /// Far-field radius in chords.
    #[arg(long, default_value_t = 10.0)]
    farfield: f64,
    /// 0: 2D quads; L >= 1: L hex layers extruded along z over --span.
    #[arg(long, default_value_t = 0)]
    layers: usize,
    /// Extrusion length along z.
    #[arg(long, default_value_t = 1.0)]
    span: f64,
    /// C-grid: cells along the wake cut.
    #[arg(long, default_value_t = 32)]
    wake: usize,
}

impl BoundaryLayerArgs {
    fn params(&self, cgrid: bool) -> polyspline::mesh::generate::BoundaryLayer {
        use polyspline::mesh::generate::{BoundaryLayer, Wall};
        let default = if cgrid {
            WallArg::Naca
        } else {
            WallArg::Ellipse
        };
        let wall = match self.wall.unwrap_or(default) {
            WallArg::Ellipse => Wall::Ellipse {
                thickness: self.thickness.unwrap_or(0.2),
            },
            WallArg::Circle => Wall::Circle,
            WallArg::Naca => Wall::Naca {
                thickness: self.thickness.unwrap_or(0.12),
            },
        };
        BoundaryLayer {
            wall,
            around: self.around,
            across: self.across,
            first_height: self.first_height,
            growth: self.growth,
            farfield: self.farfield,
            layers: self.layers,
            span: self.span,
            wake: self.wake,
        }
    }
}

#[derive(Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
enum LineSearchArg {
    Local,
    Global,
}

#[derive(Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
enum FitArg {
    None,
    Position,
    Frame,
    Smooth,
    Energy,
}

#[derive(Clone, Copy, clap::ValueEnum)]
enum EnergySolverArg {
    Lbfgs,
    Colored,
}

/// Options of `--fit energy`.
#[derive(clap::Args)]
struct EnergyArgs {
    /// Minimiser of the degeneration energy: global L-BFGS, or coloured local Newton steps.
    #[arg(long, value_enum, default_value_t = EnergySolverArg::Lbfgs)]
    energy_solver: EnergySolverArg,
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
    fn params(&self) -> anyhow::Result<EnergyParams> {
        if !(self.energy_weight >= 0.0 && self.energy_weight.is_finite()) {
            anyhow::bail!(
                "--energy-weight must be finite and non-negative, got {}",
                self.energy_weight
            );
        }
        Ok(EnergyParams {
            weight: self.energy_weight,
            solver: match self.energy_solver {
                EnergySolverArg::Lbfgs => EnergySolver::Lbfgs,
                EnergySolverArg::Colored => EnergySolver::Colored,
            },
            max_iterations: self.energy_max_iterations,
            rel_tol: self.energy_tol,
            sweep_tol: self.energy_sweep_tol,
            ..Default::default()
        })
    }
}

#[derive(Clone, Copy, clap::ValueEnum)]
enum MshVersionArg {
    #[value(name = "4.1")]
    V41,
    #[value(name = "2.2")]
    V22,
}

#[derive(Clone, Copy, clap::ValueEnum)]
enum VtuEncodingArg {
    Ascii,
    Base64,
    Appended,
}

fn run(cli: Cli) -> anyhow::Result<()> {
    match cli.command {
        Command::Info {
            mesh,
            json,
            allow_invalid,
            features,
        } => {
            let options = MeshOptions { allow_invalid };
            let linear = read_mesh(&mesh, &options)?;
            let topo = Topology::build(&linear);
            let feature_options = features.options();
            let found = feature_options.detect(&linear, &topo)?;
            let mut info = MeshInfo::new(&linear, &topo);
            info.features = Some(found.summary(&feature_options.params, &topo));
            if json {
                println!("{}", serde_json::to_string_pretty(&info)?);
            } else {
                println!("{:<22}{}", "mesh", mesh.display());
                print!("{info}");
            }
        }
        Command::Curve {
            mesh,
            output,
            quiet,
            order,
            straight,
            method,
            elastic,
            fit,
            energy,
            w_corner,
            w_boundary_corner,
            w_midpoint,
            w_frame_corner,
            w_frame_midpoint,
            w_feature,
            features,
            kink_angle,
            cg_tol,
            cg_preconditioner,
            max_bisections,
            line_search,
            min_det_fraction,
            min_quality_fraction,
            percentile_quality_fraction,
            snap_boundary,
            subdivide,
            msh_version,
            binary,
            vtu_encoding,
            volume_name,
            vtu_boundary,
            report,
            allow_invalid,
            backend,
            precision,
        } => {
            // Every output path is checked before any work, against the inputs and each other.
            if OutputFormat::from_path(&output).is_none() {
                anyhow::bail!(
                    "{}: unknown output format; use .msh (Gmsh) or .vtu (VTK)",
                    output.display()
                );
            }
            let outputs: Vec<&Path> = std::iter::once(output.as_path())
                .chain(report.as_deref())
                .collect();
            let inputs: Vec<&Path> = std::iter::once(mesh.as_path())
                .chain(features.feature_edits.as_deref())
                .collect();
            check_outputs(&outputs, &inputs)?;
            let backend = resolve_backend(backend, precision)?;
            if volume_name.is_empty() || volume_name.contains(['"', '\n', '\r']) {
                anyhow::bail!(
                    "--volume-name must be non-empty, without quotes or line breaks, got {volume_name:?}"
                );
            }
            if kink_angle.is_nan() || kink_angle <= 0.0 {
                anyhow::bail!("--kink-angle must be positive (180 turns it off), got {kink_angle}");
            }
            let mut weights = match fit {
                FitArg::Frame => FitWeights::frame(),
                FitArg::Smooth | FitArg::Energy => FitWeights::smooth(),
                _ => FitWeights::position(),
            };
            for (slot, value) in [
                (&mut weights.corner, w_corner),
                (&mut weights.boundary_corner, w_boundary_corner),
                (&mut weights.midpoint, w_midpoint),
                (&mut weights.frame_corner, w_frame_corner),
                (&mut weights.frame_midpoint, w_frame_midpoint),
                (&mut weights.feature, w_feature),
            ] {
                if let Some(v) = value {
                    if !(v >= 0.0 && v.is_finite()) {
                        anyhow::bail!("fit weights must be finite and non-negative, got {v}");
                    }
                    *slot = v;
                }
            }
            let options = CurveOptions {
                order,
                subdivide,
                geometry: if straight {
                    Geometry::Straight
                } else if fit == FitArg::None {
                    Geometry::SplineInitial
                } else {
                    Geometry::SplineFitted
                },
                method: match method {
                    MethodArg::Iga => Method::Iga,
                    MethodArg::Elastic => Method::Elastic(elastic.params(cg_tol)),
                },
                fit: FitParams {
                    weights,
                    cg: CgParams {
                        rel_tol: cg_tol,
                        preconditioner: cg_preconditioner.into(),
                        ..Default::default()
                    },
                    targets: if matches!(fit, FitArg::Smooth | FitArg::Energy) {
                        FitTargets::Smooth(SmoothParams {
                            kink_angle_deg: kink_angle,
                            ..Default::default()
                        })
                    } else {
                        FitTargets::Chords
                    },
                    ..Default::default()
                },
                features: features.options(),
                line_search: LineSearchParams {
                    max_bisections,
                    min_det_fraction,
                    min_quality_fraction,
                    percentile_quality_fraction,
                    ..Default::default()
                },
                snap_boundary,
                line_search_mode: match line_search {
                    LineSearchArg::Local => LineSearchMode::Local,
                    LineSearchArg::Global => LineSearchMode::Global,
                },
                mesh: MeshOptions { allow_invalid },
                output: OutputOptions {
                    msh_version: match msh_version {
                        MshVersionArg::V41 => MshVersion::V41,
                        MshVersionArg::V22 => MshVersion::V22,
                    },
                    binary,
                    vtu_encoding: match vtu_encoding {
                        VtuEncodingArg::Ascii => VtuEncoding::Ascii,
                        VtuEncodingArg::Base64 => VtuEncoding::Base64,
                        VtuEncodingArg::Appended => VtuEncoding::Appended,
                    },
                    volume_name,
                    vtu_boundary,
                },
                backend,
                energy: if fit == FitArg::Energy {
                    Some(energy.params()?)
                } else {
                    None
                },
            };
            // Under mpirun with several ranks: the distributed job (docs/distributed.md).
            #[cfg(feature = "mpi")]
            if polyspline::distributed::launch::distributed() {
                use polyspline::distributed::launch::{Outcome, curve};
                if let Outcome::Written(r) =
                    curve(&mesh, &output, &options, report.as_deref(), &inputs)?
                {
                    eprintln!(
                        "wrote {}: {} elements of order {}, {} nodes, {} boundary facets, on {} ranks ({:.3} s)",
                        output.display(),
                        r.curve.output_elements,
                        r.curve.order,
                        r.curve.output_nodes,
                        r.curve.boundary_facets,
                        r.ranks,
                        r.curve.timings["total"]
                    );
                }
                return Ok(());
            }
            let progress = polyspline::progress::Terminal::new(quiet);
            let r = curve_prepared(&mesh, &output, &options, &progress);
            progress.clear();
            let (r, pending_mesh) = r?;
            // Both files are complete on disk before either replaces its target, so a full disk
            // or a failing report leaves no mesh without its report.
            let pending_report = match &report {
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
                eprintln!(
                    "fit: {it} CG iterations, relative residual {res:.2e}; {} elements invalid at the full step, {} control points damped, smallest step {alpha:.4}",
                    r.invalid_at_full_step, r.damped_control_points
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
                eprintln!(
                    "elastic: E {} nu {}, {} unknowns, {} CG iterations ({:?}), relative residual {:.2e}",
                    e.young,
                    e.poisson,
                    e.unknowns,
                    e.cg.iterations,
                    e.preconditioner,
                    e.cg.rel_residual
                );
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
        Command::Compare {
            mesh,
            order,
            json,
            elastic,
            cg_tol,
            allow_invalid,
            backend,
            features,
        } => {
            let backend = resolve_backend(backend, None)?;
            let cg = CgParams {
                rel_tol: cg_tol,
                ..Default::default()
            };
            let options = CompareOptions {
                base: CurveOptions {
                    order,
                    fit: FitParams {
                        cg,
                        ..FitParams::smooth()
                    },
                    mesh: MeshOptions { allow_invalid },
                    backend,
                    features: features.options(),
                    ..Default::default()
                },
                elastic: elastic.params(cg_tol),
            };
            let report = compare(&mesh, &options)?;
            if json {
                println!("{}", serde_json::to_string_pretty(&report)?);
            } else {
                print!("{report}");
            }
        }
        Command::Generate {
            kind,
            elements,
            output,
            binary,
            layer,
        } => {
            use polyspline::mesh::generate::{Kind, boundary_layer, generate};
            let cgrid = kind == KindArg::Cgrid;
            if let Some(n) = elements
                && kind != KindArg::Ogrid
                && kind != KindArg::Cgrid
            {
                polyspline::params::check_generated_elements(n)?;
            }
            check_outputs(&[&output], &[])?;
            let kind = match kind {
                KindArg::Disc => Some(Kind::Disc),
                KindArg::Cylinder => Some(Kind::Cylinder),
                KindArg::Torus => Some(Kind::Torus),
                KindArg::Ogrid | KindArg::Cgrid => None,
            };
            let mesh = match kind {
                Some(kind) => generate(kind, elements.unwrap_or_default()),
                None => {
                    if elements.is_some() {
                        anyhow::bail!(
                            "{}: --elements applies to disc, cylinder and torus; ogrid and cgrid \
                             take --around and --across",
                            output.display()
                        );
                    }
                    let params = layer.params(cgrid);
                    let made = if cgrid {
                        boundary_layer::cgrid(&params)
                    } else {
                        boundary_layer::ogrid(&params)
                    }
                    .map_err(|e| anyhow::anyhow!("{}: {e}", output.display()))?;
                    let s = &made.spacing;
                    eprintln!(
                        "wall-normal: {} cells from {:e} growing by {}, then {} cells by {:.4} to the far field; min scaled Jacobian {:.4}, max aspect ratio {:.4e}",
                        s.geometric_cells,
                        params.first_height,
                        params.growth,
                        params.across - s.geometric_cells,
                        s.outer_growth,
                        made.mesh.min_scaled_jacobian().map_or(0.0, |m| m.0),
                        boundary_layer::max_aspect_ratio(&made.mesh),
                    );
                    made.mesh
                }
            };
            let topo = Topology::build(&mesh);
            let linear = polyspline::sample::sample(&mesh, &mesh, &topo, 1);
            let options = OutputOptions {
                binary,
                ..Default::default()
            };
            polyspline::pipeline::write_high_order(&linear, &output, &options, &[])?;
            eprintln!(
                "wrote {}: {} elements, {} vertices, {} boundary facets",
                output.display(),
                mesh.n_elements(),
                mesh.n_vertices(),
                topo.boundary_facets.len()
            );
        }
        Command::Check { mesh, json } => {
            let ho = read_high_order(&mesh)?;
            let report = CheckReport::new(&ho);
            if json {
                println!("{}", serde_json::to_string_pretty(&report)?);
            } else {
                println!("{:<22}{}", "mesh", mesh.display());
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
            }
        }
        Command::Plot {
            mesh,
            output,
            overlay,
            label,
            nodes,
            window,
            width,
            control_points,
            show_features,
            features,
        } => {
            {
                let inputs: Vec<&Path> = std::iter::once(mesh.as_path())
                    .chain(overlay.iter().map(|p| p.as_path()))
                    .chain(features.feature_edits.as_deref())
                    .collect();
                check_outputs(&[&output], &inputs)?;
            }
            if !(width.is_finite() && (16.0..=100_000.0).contains(&width)) {
                anyhow::bail!("--width {width}: must be a number of pixels in [16, 100000]");
            }
            if label.len() > overlay.len() + 1 {
                anyhow::bail!(
                    "{} labels for {} meshes: give at most one per mesh (MESH first, then each --overlay)",
                    label.len(),
                    overlay.len() + 1
                );
            }
            let paths: Vec<&PathBuf> = std::iter::once(&mesh).chain(&overlay).collect();
            let labels: Vec<String> = paths
                .iter()
                .enumerate()
                .map(|(i, p)| {
                    label.get(i).cloned().unwrap_or_else(|| {
                        p.file_name()
                            .map_or(String::new(), |n| n.to_string_lossy().into_owned())
                    })
                })
                .collect();
            let window = match window {
                None => None,
                Some(text) => {
                    let v: Vec<f64> = text
                        .split(',')
                        .map(|x| x.trim().parse::<f64>())
                        .collect::<Result<_, _>>()
                        .map_err(|e| anyhow::anyhow!("--window {text}: {e}"))?;
                    match v[..] {
                        [x0, y0, x1, y1]
                            if x0 != x1 && y0 != y1 && v.iter().all(|x| x.is_finite()) =>
                        {
                            Some([x0, y0, x1, y1])
                        }
                        _ => anyhow::bail!(
                            "--window {text}: give four numbers X0,Y0,X1,Y1 of a rectangle of non-zero size"
                        ),
                    }
                }
            };
            let base = read_high_order(&mesh)?;
            // The spline construction of a linear input (paper Fig. 1): its control points and
            // the unfitted spline map they define.
            let spline = if control_points {
                let linear = read_mesh(&mesh, &MeshOptions::default())?;
                let topo = Topology::build(&linear);
                let space = polyspline::spline::SplineSpace::build(&linear, &topo);
                let curved = polyspline::sample::sample(&space, &linear, &topo, 4);
                Some((space.control_points, curved))
            } else {
                None
            };
            let others = overlay
                .iter()
                .map(|p| read_high_order(p))
                .collect::<Result<Vec<_>, _>>()?;
            for (m, p) in std::iter::once((&base, &mesh)).chain(others.iter().zip(&overlay)) {
                if m.dim != 2 {
                    anyhow::bail!("{}: plot draws 2D meshes; this mesh is 3D", p.display());
                }
            }
            const COLOURS: [&str; 5] = ["#222222", "#1f77b4", "#9467bd", "#d62728", "#2ca02c"];
            let mut layers = Vec::new();
            for (i, m) in std::iter::once(&base).chain(&others).enumerate() {
                let colour = COLOURS[i % COLOURS.len()];
                layers.push(Layer::Mesh {
                    mesh: m,
                    colour,
                    width: 1.0,
                    label: &labels[i],
                });
                if nodes {
                    layers.push(Layer::Points {
                        points: &m.nodes,
                        colour,
                        label: &labels[i],
                        radius: 1.6,
                    });
                }
            }
            // Feature corners of a linear input, drawn on top.
            let corners: Vec<[f64; 3]> = if show_features {
                let linear = read_mesh(&mesh, &MeshOptions::default())?;
                let topo = Topology::build(&linear);
                let found = features.options().detect(&linear, &topo)?;
                found
                    .corners
                    .iter()
                    .map(|&v| linear.coords[v as usize])
                    .collect()
            } else {
                Vec::new()
            };
            if show_features {
                layers.push(Layer::Points {
                    points: &corners,
                    colour: "#ff7f0e",
                    label: "feature corners",
                    radius: 4.0,
                });
            }
            if let Some((points, curved)) = &spline {
                layers.push(Layer::Mesh {
                    mesh: curved,
                    colour: "#1f77b4",
                    width: 0.8,
                    label: "unfitted spline map",
                });
                layers.push(Layer::Points {
                    points,
                    colour: "#d62728",
                    label: "control points",
                    radius: 2.4,
                });
            }
            let svg = render_svg_window(
                &layers,
                width,
                window,
                !others.is_empty() || nodes || show_features,
            );
            let inputs: Vec<&std::path::Path> = std::iter::once(mesh.as_path())
                .chain(overlay.iter().map(|p| p.as_path()))
                .collect();
            write_atomically(&output, &inputs, |w| {
                use std::io::Write;
                w.write_all(svg.as_bytes())
            })?;
        }
    }
    Ok(())
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
    fn options(&self) -> polyspline::mesh::features::FeatureOptions {
        polyspline::mesh::features::FeatureOptions {
            params: polyspline::mesh::features::FeatureParams {
                angle_deg: self.feature_angle,
                tags: !self.no_feature_tags,
            },
            edits: self.feature_edits.clone(),
            ignore: self.ignore_features,
        }
    }
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
enum BackendArg {
    Auto,
    Cpu,
    Gpu,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
enum PrecisionArg {
    F32,
    F64,
}

/// The executor for `--backend`: `gpu` fails without an adapter; `auto` falls back to the CPU
/// unless a hardware GPU is present.
fn resolve_backend(
    backend: BackendArg,
    precision: Option<PrecisionArg>,
) -> anyhow::Result<polyspline::gpu::Backend> {
    use polyspline::gpu::{AdapterChoice, Backend, GpuContext, Precision};
    let precision = precision.map(|p| match p {
        PrecisionArg::F32 => Precision::F32,
        PrecisionArg::F64 => Precision::F64,
    });
    Ok(match backend {
        BackendArg::Cpu => Backend::Cpu,
        BackendArg::Gpu => Backend::Gpu(GpuContext::new(AdapterChoice::Any, precision)?.into()),
        BackendArg::Auto => match GpuContext::new(AdapterChoice::HardwareOnly, precision) {
            Ok(ctx) => Backend::Gpu(ctx.into()),
            Err(_) => Backend::Cpu,
        },
    })
}

/// Read a high-order mesh written by `curve` (or any linear/Lagrange quad/hex mesh).
fn read_high_order(path: &std::path::Path) -> anyhow::Result<HighOrderMesh> {
    let raw = read_raw(path)?;
    HighOrderMesh::from_raw(raw)
        .map_err(|e| anyhow::anyhow!("{}: {}: {}", path.display(), e.location, e.message))
}

fn main() -> ExitCode {
    // Mesa's Vulkan drivers print an error line while adapters are probed when the process has
    // no runtime directory; give it the temporary directory instead.
    if std::env::var_os("XDG_RUNTIME_DIR").is_none() {
        // SAFETY: no other thread exists yet (rayon and wgpu start theirs later).
        unsafe { std::env::set_var("XDG_RUNTIME_DIR", std::env::temp_dir()) };
    }
    // Printing into a closed pipe (`polyspline info M | head`) ends the process quietly, as
    // other command-line tools do, instead of panicking in `println!`.
    #[cfg(unix)]
    // SAFETY: restores the default disposition of SIGPIPE before any other thread exists.
    unsafe {
        libc::signal(libc::SIGPIPE, libc::SIG_DFL);
    }
    #[cfg(unix)]
    remove_temporaries_on_signals();
    let cli = Cli::parse();
    match run(cli) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            // One bounded line, whatever the message quotes from the input.
            let line = polyspline::io::raw::one_line(&e.to_string(), MAX_ERROR_CHARS);
            eprintln!("polyspline: error: {line}");
            ExitCode::FAILURE
        }
    }
}

/// Longest error line (characters after the prefix); paths and a quoted excerpt fit.
const MAX_ERROR_CHARS: usize = 2000;

/// SIGINT, SIGTERM and SIGHUP remove the temporary output files being written, then end the
/// process with status 128 + the signal (130, 143, 129). The signals are blocked in every
/// thread and taken by one thread with `sigwait`, so the clean-up runs as ordinary code (it
/// takes a lock and unlinks files, which an asynchronous handler could not do safely).
#[cfg(unix)]
fn remove_temporaries_on_signals() {
    // SAFETY: plain libc calls on a local signal set; called before any other thread exists,
    // so every thread started later inherits the mask.
    let set = unsafe {
        let mut set: libc::sigset_t = std::mem::zeroed();
        libc::sigemptyset(&mut set);
        for sig in [libc::SIGINT, libc::SIGTERM, libc::SIGHUP] {
            libc::sigaddset(&mut set, sig);
        }
        libc::pthread_sigmask(libc::SIG_BLOCK, &set, std::ptr::null_mut());
        set
    };
    std::thread::spawn(move || {
        loop {
            let mut sig = 0;
            // SAFETY: `set` and `sig` are valid for the call.
            if unsafe { libc::sigwait(&set, &mut sig) } != 0 {
                continue;
            }
            let removed = polyspline::io::output::remove_registered_temporaries();
            let name = match sig {
                libc::SIGINT => "SIGINT",
                libc::SIGTERM => "SIGTERM",
                _ => "SIGHUP",
            };
            eprintln!(
                "polyspline: interrupted by {name}{}",
                if removed > 0 {
                    "; the unfinished output was removed"
                } else {
                    ""
                }
            );
            std::process::exit(128 + sig);
        }
    });
}
