//! The `curve` job end to end: read → topology → element maps → sample → write, with timings.
//!
//! Input: a mesh path and [`CurveOptions`]. Output: the written high-order mesh file and a
//! [`CurveReport`]. The output file is written atomically and never onto the input.
//! [`curve_in_memory`] is the same job without writing (used by `compare`).
//!
//! With [`Method::Elastic`] the spline is fitted and sampled as usual, then only its boundary
//! nodes are kept: the straight order-P mesh is moved onto them by linear elasticity
//! ([`crate::elastic`]) and each of its Lagrange elements must pass the det J certificate, or the
//! job fails with [`CurveError::Invalid`] and writes nothing.

use crate::elastic::{ElasticError, ElasticInfo, ElasticParams, elastic_analogy};
use crate::energy::{EnergyError, EnergyInfo, EnergyParams};
use crate::fit::{FitParams, FitTargets, FitWeights, fit_with_targets};
use crate::gpu::{AdapterReport, Backend, Precision};
use crate::io::gmsh_write::{DEFAULT_VOLUME_NAME, MshVersion, write_msh_named};
use crate::io::output::{WriteError, write_atomically};
use crate::io::vtu_write::{VtuCells, VtuEncoding, write_vtu_cells};
use crate::io::{ReadError, read_mesh};
use crate::mesh::{MeshOptions, Topology};
use crate::quality::sample_det_jacobian;
use crate::sample::{BezierElements, HighOrderMesh, MAX_ORDER, sample};
use crate::solve::CgError;
use crate::spline::{SplineSpace, kinks};
use crate::validity::blend::{BlendError, BlendInfo, Blended, blend_search};
use crate::validity::{
    Certifier, CpuCertifier, LineSearchInfo, LineSearchParams, ValidityError, certify_screened,
    lagrange_element_bounds, line_search_with, local_line_search_with,
};
use serde::Serialize;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// What geometry to sample.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Geometry {
    /// The input's straight-sided (bilinear/trilinear) elements at the requested order.
    Straight,
    /// The spline map from the initial control points (vertex averages), not fitted.
    SplineInitial,
    /// The spline map fitted by least squares with these weights, then certified.
    SplineFitted,
}

/// How the fitted step is shortened where it would invalidate elements.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, clap::ValueEnum)]
#[serde(rename_all = "snake_case")]
pub enum LineSearchMode {
    /// One α for all control points (paper §2.3).
    Global,
    /// A factor per control point, halved only around elements that are not certified
    /// ([`crate::validity::local_line_search`]).
    #[value(
        help = "A factor per control point, halved only around elements that are not certified"
    )]
    Local,
}

/// How the interior of the curved mesh is placed.
#[derive(Clone, Copy, Debug)]
pub enum Method {
    /// Sample the (fitted) spline map everywhere (the paper's method).
    Iga,
    /// Sample the spline only on the boundary; move the interior nodes of the straight order-P
    /// mesh by linear elasticity (paper §2.5, the baseline).
    Elastic(ElasticParams),
}

impl Method {
    pub fn name(&self) -> &'static str {
        match self {
            Method::Iga => "iga",
            Method::Elastic(_) => "elastic",
        }
    }
}

/// Output file options.
#[derive(Clone, Debug)]
pub struct OutputOptions {
    pub msh_version: MshVersion,
    pub binary: bool,
    pub vtu_encoding: VtuEncoding,
    /// Name of the MSH volume group where the input names no region (`fluid`, as PyFR needs).
    pub volume_name: String,
    /// Also write the boundary facets to this VTU file (the main VTU holds the volume only).
    pub vtu_boundary: Option<PathBuf>,
}

impl Default for OutputOptions {
    fn default() -> Self {
        OutputOptions {
            msh_version: MshVersion::V41,
            binary: false,
            vtu_encoding: VtuEncoding::Base64,
            volume_name: DEFAULT_VOLUME_NAME.into(),
            vtu_boundary: None,
        }
    }
}

/// Options of the `curve` job.
#[derive(Clone, Debug)]
pub struct CurveOptions {
    pub order: usize,
    /// Order 1 output split into `subdivide`^d elements per input element.
    pub subdivide: Option<usize>,
    pub geometry: Geometry,
    /// IGA everywhere, or the elastic analogy inside the IGA boundary.
    pub method: Method,
    /// Weights of the fit (used with [`Geometry::SplineFitted`]).
    pub fit: FitParams,
    pub line_search: LineSearchParams,
    pub line_search_mode: LineSearchMode,
    /// Move boundary vertex nodes back to the input vertices where that stays certified valid.
    pub snap_boundary: bool,
    /// Sharp features kept by the spline space and the fit (`docs/features.md`).
    pub features: crate::mesh::features::FeatureOptions,
    pub mesh: MeshOptions,
    pub output: OutputOptions,
    /// Executor of sampling, certification and the CG solve.
    pub backend: Backend,
    /// After the certified least-squares fit, minimise the element degeneration energy
    /// ([`crate::energy`]); `None` (the default) keeps the least-squares result.
    pub energy: Option<EnergyParams>,
}

impl Default for CurveOptions {
    /// The CLI's defaults: order 2, the smooth-boundary fit, local line search, CPU backend.
    fn default() -> Self {
        CurveOptions {
            order: 2,
            subdivide: None,
            geometry: Geometry::SplineFitted,
            method: Method::Iga,
            fit: FitParams::smooth(),
            line_search: LineSearchParams::default(),
            line_search_mode: LineSearchMode::Local,
            snap_boundary: false,
            features: Default::default(),
            mesh: MeshOptions::default(),
            output: OutputOptions::default(),
            backend: Backend::default(),
            energy: None,
        }
    }
}

/// Everything that can stop the `curve` job.
#[derive(Debug, thiserror::Error)]
pub enum CurveError {
    #[error(transparent)]
    Read(#[from] ReadError),
    #[error(transparent)]
    Write(#[from] WriteError),
    #[error("{0}")]
    Options(String),
    /// Duplicated elements, non-manifold facets, edges or vertices, or no boundary.
    #[error("{}: cannot curve: {what}", input.display())]
    NotCurvable { input: PathBuf, what: String },
    #[error(transparent)]
    Features(#[from] crate::mesh::features::FeatureError),
    #[error("{}: GPU: {source}", input.display())]
    Gpu {
        input: PathBuf,
        source: crate::gpu::GpuError,
    },
    #[error("{}: fit: {source}", input.display())]
    Solve { input: PathBuf, source: CgError },
    #[error("{}: energy: {source}", input.display())]
    Energy { input: PathBuf, source: EnergyError },
    #[error("{}: {source}", input.display())]
    Elastic {
        input: PathBuf,
        source: ElasticError,
    },
    #[error("{}: {source}", input.display())]
    Blend { input: PathBuf, source: BlendError },
    #[error("{}: {source}", input.display())]
    Validity {
        input: PathBuf,
        source: ValidityError,
    },
    #[error("{}: the {what} is not certified valid on {count} element(s) (first: {first}); nothing was written", input.display())]
    Invalid {
        input: PathBuf,
        what: String,
        count: usize,
        first: String,
    },
}

impl CurveError {
    /// The output would contain the elements `bad`, not certified valid: name the first few.
    fn invalid(input: &Path, what: &str, bad: &[usize]) -> CurveError {
        CurveError::Invalid {
            input: input.to_owned(),
            what: what.into(),
            count: bad.len(),
            first: bad
                .iter()
                .take(8)
                .map(|e| e.to_string())
                .collect::<Vec<_>>()
                .join(", "),
        }
    }
}

/// What `curve` did, for `--report` and the terminal.
#[derive(Clone, Debug, Serialize)]
pub struct CurveReport {
    pub input: PathBuf,
    pub output: PathBuf,
    pub dimension: usize,
    pub elements: usize,
    pub order: usize,
    pub subdivide: Option<usize>,
    pub geometry: Geometry,
    /// `iga` or `elastic`.
    pub method: &'static str,
    /// The elastic solve, with `--method elastic`.
    pub elastic: Option<ElasticInfo>,
    pub output_nodes: usize,
    pub output_elements: usize,
    pub boundary_facets: usize,
    pub control_points: usize,
    pub spline_elements: usize,
    pub q2_elements: usize,
    /// Elements made Q2 because their initial spline map was not certified valid.
    pub demoted_elements: usize,
    /// Elements made Q2 because they touch a kink of a boundary grid line (smooth fit), counting
    /// only elements that would otherwise be spline elements.
    pub kink_elements: usize,
    /// With `--snap-boundary`: boundary vertices moved back onto the input vertices.
    pub snapped_boundary_vertices: Option<usize>,
    /// Sharp features found and how the output keeps them (spline geometries).
    pub features: Option<crate::mesh::features::FeatureReport>,
    /// Fit weights, when fitted.
    pub fit_weights: Option<FitWeights>,
    /// Fit targets (chords or smooth-boundary reconstruction), when fitted.
    pub fit_targets: Option<FitTargets>,
    pub cg_iterations: Option<usize>,
    /// Stored entries of the normal-equation matrix (one matrix for x, y, z).
    pub matrix_nonzeros: Option<usize>,
    pub cg_rel_residual: Option<f64>,
    pub line_search_mode: LineSearchMode,
    /// Step of the certified search (1 = the full least-squares fit everywhere): with the
    /// blend of least-squares fits, half its smallest factor (0.5 = the target map, 0 = the
    /// straight elevation, somewhere); with `--fit energy`, the global step or the smallest
    /// control point step of the local search.
    pub line_search_alpha: Option<f64>,
    /// Elements not certified valid at the full least-squares step.
    pub invalid_at_full_step: usize,
    /// Points held back from the full step: shared Bernstein points of the certified blend
    /// (least-squares fits), or control points of the local search (`--fit energy`).
    pub damped_control_points: usize,
    pub line_search: Option<LineSearchInfo>,
    /// Elements whose curving the certified blend reduced (some Bernstein point held back
    /// towards the straight elevation; `validity::blend`).
    pub reduced_elements: usize,
    /// The certified blend between the straight elevation and the fitted map: elements and
    /// points reduced, by how much, the worst ones with their coordinates.
    pub blend: Option<BlendInfo>,
    /// The degeneration-energy minimisation, with `--fit energy`.
    pub energy: Option<EnergyInfo>,
    /// Why `--fit energy` fell back to the blended least-squares fit, when it did.
    pub energy_skipped: Option<String>,
    /// Elements of the written mesh not certified valid (always 0: otherwise nothing is written).
    pub invalid_elements: usize,
    /// Smallest certified lower bound of det J over the written elements (spline geometry).
    /// It is the exact Bernstein certificate's (the screen, `validity::screen`, decides only
    /// elements whose exact bound is larger).
    pub min_det_jacobian_bound: Option<f64>,
    /// Minimum scaled Jacobian of the input (corners) and of the output (sampled).
    pub input_min_scaled_jacobian: f64,
    pub min_scaled_jacobian: f64,
    /// Bounding-box diagonal of the input: the `boundary_*` distances below are relative to it.
    pub bounding_box_diagonal: f64,
    /// Distance of the output's boundary vertex nodes from the input's boundary vertices
    /// (0 where `--snap-boundary` snapped them), max and rms.
    pub boundary_vertex_deviation_max: f64,
    pub boundary_vertex_deviation_rms: f64,
    /// Largest distance of any written boundary node (vertex, edge or face node) from the
    /// input's linear boundary: how far the curving moved the wall ([`crate::deviation`]).
    pub boundary_node_distance_max: f64,
    /// The same over the output's boundary facets sampled on the lattice of order 2p.
    pub boundary_sample_distance_max: f64,
    /// Seconds per stage, and `total`.
    pub timings: BTreeMap<String, f64>,
    /// `cpu` or `gpu`; with `gpu`, the adapter and the kernels' precision.
    pub backend: String,
    pub adapter: Option<AdapterReport>,
    pub gpu_precision: Option<Precision>,
}

/// Output format from the file extension.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum OutputFormat {
    Msh,
    Vtu,
}

impl OutputFormat {
    pub fn from_path(path: &Path) -> Option<OutputFormat> {
        match path.extension()?.to_str()?.to_ascii_lowercase().as_str() {
            "msh" => Some(OutputFormat::Msh),
            "vtu" => Some(OutputFormat::Vtu),
            _ => None,
        }
    }
}

/// Write a high-order mesh to `path` in the format its extension names, and its boundary
/// facets to `options.vtu_boundary` when that is set.
pub fn write_high_order(
    mesh: &HighOrderMesh,
    path: &Path,
    options: &OutputOptions,
    inputs: &[&Path],
) -> Result<(), WriteError> {
    prepare_high_order(mesh, path, options, inputs)?.commit()
}

/// [`write_high_order`] into a synced temporary beside `path`, renamed into place by
/// [`crate::io::output::PendingFile::commit`] (so several outputs can all be written before
/// any replaces its target).
pub fn prepare_high_order(
    mesh: &HighOrderMesh,
    path: &Path,
    options: &OutputOptions,
    inputs: &[&Path],
) -> Result<crate::io::output::PendingFile, WriteError> {
    let format = OutputFormat::from_path(path).ok_or_else(|| WriteError::Unsupported {
        path: path.to_owned(),
        what: "unknown output format; use .msh (Gmsh) or .vtu (VTK)".into(),
    })?;
    if format == OutputFormat::Msh && mesh.dim == 3 && mesh.order > 9 {
        return Err(WriteError::Unsupported {
            path: path.to_owned(),
            what: format!(
                "Gmsh has no hexahedron of order {}; the highest is 9 (use .vtu for order 10)",
                mesh.order
            ),
        });
    }
    if let Some(bpath) = &options.vtu_boundary {
        if OutputFormat::from_path(bpath) != Some(OutputFormat::Vtu) {
            return Err(WriteError::Unsupported {
                path: bpath.clone(),
                what: "the boundary file is written as VTU; give it the extension .vtu".into(),
            });
        }
        if bpath == path {
            return Err(WriteError::Unsupported {
                path: bpath.clone(),
                what: "the boundary file would overwrite the mesh output; choose another path"
                    .into(),
            });
        }
        // The secondary boundary file is written (atomically) before the mesh is prepared.
        let mut not_onto: Vec<&Path> = inputs.to_vec();
        not_onto.push(path);
        write_atomically(bpath, &not_onto, |w| {
            write_vtu_cells(mesh, options.vtu_encoding, VtuCells::Boundary, w)
        })?;
    }
    crate::io::output::prepare(path, inputs, |w| match format {
        OutputFormat::Msh => write_msh_named(
            mesh,
            options.msh_version,
            options.binary,
            &options.volume_name,
            w,
        ),
        OutputFormat::Vtu => write_vtu_cells(mesh, options.vtu_encoding, VtuCells::Volume, w),
    })
}

/// A curved mesh in memory with the input it was made from (the `curve` job without writing).
pub struct Curved {
    pub mesh: crate::mesh::LinearMesh,
    pub topo: Topology,
    pub ho: HighOrderMesh,
    /// The report; `output` is empty and `timings` has no `write`.
    pub report: CurveReport,
}

/// Run the `curve` job.
pub fn curve(
    input: &Path,
    output: &Path,
    options: &CurveOptions,
) -> Result<CurveReport, CurveError> {
    curve_with_progress(input, output, options, &crate::progress::Silent)
}

/// [`curve`], reporting stage progress to `progress`.
pub fn curve_with_progress(
    input: &Path,
    output: &Path,
    options: &CurveOptions,
    progress: &dyn crate::progress::Progress,
) -> Result<CurveReport, CurveError> {
    let (report, pending) = curve_prepared(input, output, options, progress)?;
    pending.commit()?;
    Ok(report)
}

/// [`curve_with_progress`] up to a complete, synced temporary of the output that
/// [`crate::io::output::PendingFile::commit`] renames into place (dropped, it is removed): the
/// caller can write other outputs (the report) before either replaces its target.
pub fn curve_prepared(
    input: &Path,
    output: &Path,
    options: &CurveOptions,
    progress: &dyn crate::progress::Progress,
) -> Result<(CurveReport, crate::io::output::PendingFile), CurveError> {
    if OutputFormat::from_path(output).is_none() {
        return Err(WriteError::Unsupported {
            path: output.to_owned(),
            what: "unknown output format; use .msh (Gmsh) or .vtu (VTK)".into(),
        }
        .into());
    }
    // Before any work: the output must not be the input and must be creatable.
    crate::io::output::check_outputs(&[output], &[input])?;
    let start = Instant::now();
    let Curved { ho, mut report, .. } = curve_in_memory_with_progress(input, options, progress)?;
    let t = Instant::now();
    let pending = prepare_high_order(&ho, output, &options.output, &[input])?;
    report
        .timings
        .insert("write".into(), t.elapsed().as_secs_f64());
    report
        .timings
        .insert("total".into(), start.elapsed().as_secs_f64());
    report.output = output.to_owned();
    Ok((report, pending))
}

/// Everything of the `curve` job but writing the output.
pub fn curve_in_memory(input: &Path, options: &CurveOptions) -> Result<Curved, CurveError> {
    curve_in_memory_with_progress(input, options, &crate::progress::Silent)
}

/// [`curve_in_memory`], reporting stage progress to `progress`.
pub fn curve_in_memory_with_progress(
    input: &Path,
    options: &CurveOptions,
    progress: &dyn crate::progress::Progress,
) -> Result<Curved, CurveError> {
    let order = options.subdivide.unwrap_or(options.order);
    if options.subdivide.is_some() && options.order != 1 {
        return Err(CurveError::Options(
            "--subdivide gives order-1 output; use it with --order 1".into(),
        ));
    }
    crate::params::check_curve(options).map_err(|e| CurveError::Options(e.to_string()))?;
    if !(1..=MAX_ORDER).contains(&order) {
        return Err(CurveError::Options(format!(
            "order {order} is out of range 1..={MAX_ORDER}"
        )));
    }
    let elastic = match options.method {
        Method::Elastic(params) => Some(params),
        Method::Iga => None,
    };
    if elastic.is_some() && options.geometry == Geometry::Straight {
        return Err(CurveError::Options(
            "--method elastic moves the straight mesh onto the spline boundary; it cannot be combined with --straight".into(),
        ));
    }
    if elastic.is_some() && !(1..=crate::elastic::MAX_ELASTIC_ORDER).contains(&order) {
        return Err(CurveError::Options(format!(
            "--method elastic supports orders (or --subdivide) 1..={}, not {order}",
            crate::elastic::MAX_ELASTIC_ORDER,
        )));
    }
    let start = Instant::now();
    let mut timings = BTreeMap::new();
    let mut lap = {
        let mut t = Instant::now();
        move |name: &str, timings: &mut BTreeMap<String, f64>| {
            timings.insert(name.to_string(), t.elapsed().as_secs_f64());
            progress.finished(name);
            t = Instant::now();
        }
    };
    let mesh = read_mesh(input, &options.mesh)?;
    lap("read", &mut timings);
    let topo = Topology::build(&mesh);
    crate::mesh::manifold::check_curvable(&mesh, &topo).map_err(|what| {
        CurveError::NotCurvable {
            input: input.to_owned(),
            what,
        }
    })?;
    lap("topology", &mut timings);
    let input_msj = mesh.min_scaled_jacobian().map_or(f64::NAN, |m| m.0);
    let mut space = None;
    let mut fit_info = None;
    let mut ls_info = None;
    let mut min_det_bound = None;
    let mut demoted = 0;
    let mut ls_alpha = None;
    let mut ls_invalid_full = 0;
    let mut ls_damped = 0;
    let mut energy_info = None;
    let mut energy_skipped = None;
    let mut blend_lambda: Option<Vec<f32>> = None;
    let mut blend_info = None;
    let gpu = options.backend.gpu();
    let gpu_certifier = gpu.map(crate::gpu::jacobian_check::GpuCertifier::new);
    let certifier: &dyn Certifier = match &gpu_certifier {
        Some(c) => c,
        None => &CpuCertifier,
    };
    // Screened certificate (crate::validity::screen): decisions "lower > t" for t ≤ target(e)
    // and the smallest bound are the exact certificate's.
    let certify_above = |s: &SplineSpace, target: &(dyn Fn(usize) -> f64 + Sync)| {
        let all: Vec<usize> = (0..s.n_elements()).collect();
        let net = |e: usize| s.element_bezier(e);
        let depth = options.line_search.certificate_depth;
        let mut c = certify_screened(certifier, s.dim, &all, &net, depth, target);
        c.refine_smallest(certifier, s.dim, &all, &net, depth, 1);
        c.bounds
    };
    let certify_all = |s: &SplineSpace| certify_above(s, &|_| 0.0);
    let features = match options.geometry {
        Geometry::Straight => None,
        _ => Some(options.features.detect(&mesh, &topo)?).filter(|f| !f.is_empty()),
    };
    let used = features.as_ref().filter(|_| !options.features.ignore);
    let crease = used.map_or_else(Vec::new, |f| f.crease_elements(&topo));
    let fit_params = FitParams {
        features: used.cloned().map(std::sync::Arc::new),
        ..options.fit.clone()
    };
    // With the smooth fit, elements at kinks of the boundary grid lines start as Q2; vertices
    // on sharp features are left to the feature handling.
    let kinks = match options.fit.targets {
        FitTargets::Smooth(p) if options.geometry == Geometry::SplineFitted => {
            let mut exclude = kinks::feature_vertices(&mesh, &topo, p.feature_angle_deg);
            if let Some(f) = used {
                for (x, &m) in exclude.iter_mut().zip(&f.vertex_mask) {
                    *x |= m;
                }
            }
            kinks::detect(&mesh, &topo, p.kink_angle_deg, &exclude)
        }
        _ => kinks::Kinks::default(),
    };
    let build = |demote: &[bool]| {
        SplineSpace::build_with_q2(
            &mesh,
            &topo,
            &[
                (&crease, crate::spline::Q2Reason::FeatureCrease),
                (&kinks.elements, crate::spline::Q2Reason::BoundaryKink),
                (demote, crate::spline::Q2Reason::InvalidSplineMap),
            ],
        )
    };
    // The fit's smooth targets, shared by the fit and the target map of the blend.
    // The blend's middle state carries the smooth boundary whatever the fit's own targets
    // (with the paper's chord targets it is built with the default reconstruction).
    let targets = match options.geometry {
        Geometry::SplineFitted => crate::fit::smooth_targets(&mesh, &topo, &fit_params),
        _ => None,
    };
    let blend_targets = match (&targets, options.geometry) {
        (None, Geometry::SplineFitted) => crate::fit::smooth_targets(
            &mesh,
            &topo,
            &FitParams {
                targets: FitTargets::Smooth(Default::default()),
                ..fit_params.clone()
            },
        ),
        _ => None,
    };
    let target_map = crate::fit::TargetMap {
        mesh: &mesh,
        topo: &topo,
        smooth: targets.as_ref().or(blend_targets.as_ref()),
    };
    if options.geometry != Geometry::Straight {
        let mut demote = vec![false; mesh.n_elements()];
        let mut s = build(&demote);
        lap("spline", &mut timings);
        // The least-squares fit of the space's control points (planar patches projected back).
        let solve_fit = |s: &SplineSpace| {
            let (mut c_star, info) = fit_with_targets(
                s,
                &mesh,
                &topo,
                &fit_params,
                targets.as_ref(),
                |k, rhs, x, cg| match gpu {
                    Some(ctx) => crate::gpu::cg::pcg(ctx, k, rhs, x, cg, |_, _| {}),
                    None => crate::solve::pcg(k, rhs, x, cg, |i, r| progress.cg(i, r)),
                },
            )
            .map_err(|source| CurveError::Solve {
                input: input.to_owned(),
                source,
            })?;
            if let Some(f) = used {
                crate::fit::features::project_onto_planes(s, &topo, f, &mut c_star);
            }
            Ok::<_, CurveError>((c_star, info))
        };
        // The certified blend from the straight elevation to the fitted map (validity::blend):
        // valid for every input whose straight elevation is certified.
        let blend = |s: &SplineSpace| {
            let mut blended = Blended::new(&mesh, &target_map, s, &mesh, &topo, Vec::new());
            let info = blend_search(
                certifier,
                &mut blended,
                &options
                    .line_search
                    .blend(options.line_search_mode == LineSearchMode::Global),
            )
            .map_err(|source| CurveError::Blend {
                input: input.to_owned(),
                source,
            })?;
            Ok::<_, CurveError>((std::mem::take(&mut blended.factors), info))
        };
        if options.geometry == Geometry::SplineFitted && options.energy.is_none() {
            let (c_star, info) = solve_fit(&s)?;
            lap("fit", &mut timings);
            *timings.entry("fit_assembly".into()).or_insert(0.0) += info.assembly_seconds;
            *timings.entry("fit_cg".into()).or_insert(0.0) += info.solve_seconds;
            s.control_points = c_star;
            let (lambda, bi) = blend(&s)?;
            blend_lambda = Some(lambda);
            fit_info = Some(info);
            blend_info = Some(bi);
            lap("validity", &mut timings);
        } else if options.geometry == Geometry::SplineFitted {
            // Fit; take the full step when certified, else bisect towards the initial map.
            // Where the initial map itself is not certified valid, those elements become
            // constrained Q2 elements (the input's own shape) and the fit is repeated; when
            // that does not give a certified start, the energy is skipped and the
            // least-squares fit is blended with the straight elevation instead.
            let mut round = 0;
            loop {
                let (c_star, info) = solve_fit(&s)?;
                lap("fit", &mut timings);
                *timings.entry("fit_assembly".into()).or_insert(0.0) += info.assembly_seconds;
                *timings.entry("fit_cg".into()).or_insert(0.0) += info.solve_seconds;
                let net = |e: usize, cps: &[[f64; 3]]| s.element_bezier_with(e, cps);
                let thresholds =
                    acceptance_thresholds(&mesh, options.line_search.min_det_fraction, |t| {
                        certify_above(&s, t)
                    });
                let result = match options.line_search_mode {
                    LineSearchMode::Global => line_search_with(
                        certifier,
                        s.dim,
                        s.n_elements(),
                        net,
                        &s.control_points,
                        &c_star,
                        &thresholds,
                        &options.line_search,
                    )
                    .map(|(c, ls)| {
                        (
                            c,
                            ls.alpha,
                            ls.min_det_lower_bound,
                            ls.invalid_at_full_step,
                            0,
                            Some(ls),
                        )
                    }),
                    LineSearchMode::Local => {
                        let support = |e: usize| {
                            let mut rows = crate::spline::ElementRows::default();
                            s.extraction.rows(e, &mut rows);
                            let mut ids = rows.cols;
                            ids.sort_unstable();
                            ids.dedup();
                            ids
                        };
                        local_line_search_with(
                            certifier,
                            s.dim,
                            s.n_elements(),
                            net,
                            support,
                            &s.control_points,
                            &c_star,
                            &thresholds,
                            &options.line_search,
                        )
                        .map(|(c, ls)| {
                            (
                                c,
                                ls.min_step,
                                ls.min_det_lower_bound,
                                ls.invalid_at_full_step,
                                ls.damped_control_points,
                                None,
                            )
                        })
                    }
                };
                match result {
                    Ok((c, alpha, bound, invalid_full, damped, ls)) => {
                        let c = match &options.energy {
                            None => c,
                            Some(params) => {
                                lap("validity", &mut timings);
                                let (c, info) = minimize_energy(
                                    &s,
                                    &mesh,
                                    &topo,
                                    &fit_params,
                                    options,
                                    params,
                                    certifier,
                                    &c_star,
                                    &thresholds,
                                    &c,
                                )
                                .map_err(|source| CurveError::Energy {
                                    input: input.to_owned(),
                                    source,
                                })?;
                                energy_info = Some(info);
                                lap("energy", &mut timings);
                                c
                            }
                        };
                        s.control_points = c;
                        min_det_bound = Some(if options.energy.is_some() {
                            certify_all(&s)
                                .iter()
                                .map(|b| b.lower)
                                .fold(f64::INFINITY, f64::min)
                        } else {
                            bound
                        });
                        fit_info = Some(info);
                        ls_alpha = Some(alpha);
                        ls_invalid_full = invalid_full;
                        ls_damped = damped;
                        ls_info = ls;
                        lap("validity", &mut timings);
                        break;
                    }
                    Err(ValidityError::InitialInvalid { .. }) if round < MAX_DEMOTION_ROUNDS => {
                        let bounds = certify_all(&s);
                        let bad: Vec<usize> = (0..bounds.len())
                            .filter(|&e| !bounds[e].certified_positive())
                            .collect();
                        let is_q2 = |e: usize| !s.is_spline(e);
                        demote_with_rings(&mesh, &topo, &bad, round, &is_q2, &mut demote);
                        s = build(&demote);
                        round += 1;
                        lap("validity", &mut timings);
                    }
                    Err(ValidityError::InitialInvalid { count, .. }) => {
                        energy_skipped = Some(format!(
                            "the initial spline map is not certified valid on {count} element(s); the least-squares fit was blended with the straight elevation instead"
                        ));
                        s.control_points = c_star;
                        let (lambda, bi) = blend(&s)?;
                        blend_lambda = Some(lambda);
                        fit_info = Some(info);
                        blend_info = Some(bi);
                        lap("validity", &mut timings);
                        break;
                    }
                }
            }
            demoted = demote.iter().filter(|&&d| d).count();
        } else {
            let bounds = certify_all(&s);
            let bad: Vec<usize> = (0..bounds.len())
                .filter(|&e| !bounds[e].certified_positive())
                .collect();
            if !bad.is_empty() {
                // The unfitted map is what was asked for: refuse rather than change it.
                return Err(CurveError::invalid(
                    input,
                    "initial spline map (use --fit position to fit it)",
                    &bad,
                ));
            }
            min_det_bound = Some(bounds.iter().map(|b| b.lower).fold(f64::INFINITY, f64::min));
            lap("validity", &mut timings);
        }
        // The report's line-search figures of a blended fit (least squares, or the energy's
        // fallback).
        if let Some(bi) = &blend_info {
            min_det_bound = Some(bi.min_det_lower_bound);
            ls_alpha = Some(0.5 * bi.min_factor);
            ls_invalid_full = bi.invalid_at_full_step;
            ls_damped = bi.reduced_points;
        }
        space = Some(s);
    }
    let blended = space
        .as_ref()
        .zip(blend_lambda)
        .map(|(s, factors)| Blended::new(&mesh, &target_map, s, &mesh, &topo, factors));
    let source: &dyn BezierElements = match (&blended, &space) {
        (Some(b), _) => b,
        (None, Some(s)) => s,
        (None, None) => &mesh,
    };
    let mut ho =
        match gpu {
            Some(ctx) => crate::gpu::evaluate::sample(ctx, source, &mesh, &topo, order).map_err(
                |source| CurveError::Gpu {
                    input: input.to_owned(),
                    source,
                },
            )?,
            None => sample(source, &mesh, &topo, order),
        };
    if options.subdivide.is_some() && elastic.is_none() {
        ho = ho.subdivided();
    }
    lap("sample", &mut timings);
    let snapped = if options.snap_boundary {
        let n = snap_boundary(&mesh, &topo, &mut ho, options.line_search.certificate_depth);
        lap("snap", &mut timings);
        Some(n)
    } else {
        None
    };
    let mut elastic_info = None;
    if let Some(params) = elastic {
        // The straight order-P mesh, its boundary moved onto the sampled spline's boundary.
        let straight = sample(&mesh, &mesh, &topo, order);
        lap("elastic_sample", &mut timings);
        let (moved, info) =
            elastic_analogy(&straight, &ho, &params).map_err(|source| CurveError::Elastic {
                input: input.to_owned(),
                source,
            })?;
        lap("elastic", &mut timings);
        timings.insert("elastic_assembly".into(), info.assembly_seconds);
        timings.insert("elastic_cg".into(), info.solve_seconds);
        let depth = options.line_search.certificate_depth;
        let bounds: Vec<_> = {
            use rayon::prelude::*;
            (0..moved.n_elements())
                .into_par_iter()
                .map(|e| lagrange_element_bounds(&moved, e, depth))
                .collect()
        };
        let bad: Vec<usize> = (0..bounds.len())
            .filter(|&e| !bounds[e].certified_positive())
            .collect();
        if !bad.is_empty() {
            return Err(CurveError::invalid(input, "elastic-analogy mesh", &bad));
        }
        min_det_bound = Some(bounds.iter().map(|b| b.lower).fold(f64::INFINITY, f64::min));
        lap("elastic_validity", &mut timings);
        ho = moved;
        if options.subdivide.is_some() {
            ho = ho.subdivided();
        }
        elastic_info = Some(info);
    }
    let quality = sample_det_jacobian(&ho);
    let min_sj = quality
        .iter()
        .map(|q| q.min_scaled_jacobian)
        .fold(f64::INFINITY, f64::min);
    let invalid: Vec<usize> = (0..quality.len())
        .filter(|&e| !(quality[e].min_det_jacobian > 0.0))
        .collect();
    if !invalid.is_empty() {
        return Err(CurveError::invalid(input, "sampled output", &invalid));
    }
    let deviation = crate::deviation::boundary_deviation(&mesh, &topo, &ho);
    lap("quality", &mut timings);
    timings.insert("total".into(), start.elapsed().as_secs_f64());
    let report = CurveReport {
        input: input.to_owned(),
        output: PathBuf::new(),
        dimension: mesh.dim,
        elements: mesh.n_elements(),
        order: ho.order,
        subdivide: options.subdivide,
        geometry: options.geometry,
        method: options.method.name(),
        elastic: elastic_info,
        output_nodes: ho.nodes.len(),
        output_elements: ho.n_elements(),
        boundary_facets: ho.n_boundary(),
        control_points: space.as_ref().map_or(0, |s| s.n_control_points()),
        spline_elements: space.as_ref().map_or(0, |s| s.n_spline_elements()),
        q2_elements: space.as_ref().map_or(0, |s| s.n_q2_elements()),
        demoted_elements: demoted,
        // Counted in the built space: elements Q2 for other reasons already are not kinks'.
        kink_elements: space.as_ref().map_or(0, |s| {
            s.classes
                .iter()
                .filter(|c| {
                    **c == crate::spline::ElementClass::Q2(crate::spline::Q2Reason::BoundaryKink)
                })
                .count()
        }),
        snapped_boundary_vertices: snapped,
        features: features.as_ref().map(|f| {
            let (vertex, planarity) = f.deviations(&mesh, &ho);
            crate::mesh::features::FeatureReport {
                found: f.summary(&options.features.params, &topo),
                feature_vertex_deviation_max: vertex,
                planarity_max: planarity,
            }
        }),
        fit_weights: fit_info.as_ref().map(|_| options.fit.weights),
        fit_targets: fit_info.as_ref().map(|_| options.fit.targets),
        cg_iterations: fit_info.as_ref().map(|f| f.cg.iterations),
        matrix_nonzeros: fit_info.as_ref().map(|f| f.nonzeros),
        cg_rel_residual: fit_info.as_ref().map(|f| f.cg.rel_residual),
        line_search_mode: options.line_search_mode,
        line_search_alpha: ls_alpha,
        invalid_at_full_step: ls_invalid_full,
        damped_control_points: ls_damped,
        line_search: ls_info,
        reduced_elements: blend_info.as_ref().map_or(0, |b| b.reduced_elements),
        blend: blend_info,
        energy: energy_info,
        energy_skipped,
        invalid_elements: 0,
        min_det_jacobian_bound: min_det_bound,
        input_min_scaled_jacobian: input_msj,
        min_scaled_jacobian: min_sj,
        bounding_box_diagonal: deviation.diagonal,
        boundary_vertex_deviation_max: deviation.vertex_max,
        boundary_vertex_deviation_rms: deviation.vertex_rms,
        boundary_node_distance_max: deviation.node_max,
        boundary_sample_distance_max: deviation.sample_max,
        timings,
        backend: options.backend.name().into(),
        adapter: gpu.map(|g| g.adapter.clone()),
        gpu_precision: gpu.map(|g| g.precision),
    };
    Ok(Curved {
        mesh,
        topo,
        ho,
        report,
    })
}

/// Distance of the output's vertex nodes on the boundary from the input's boundary vertices
/// (node ids of vertices equal the input vertex ids), relative to the bounding-box diagonal:
/// (max, rms). The report's other boundary measures are in [`crate::deviation`].
pub fn boundary_deviation(
    mesh: &crate::mesh::LinearMesh,
    topo: &Topology,
    ho: &HighOrderMesh,
) -> (f64, f64) {
    crate::deviation::vertex_deviation(mesh, topo, ho)
}

/// The energy minimisation of `--fit energy` from the certified least-squares result `start`;
/// the least-squares line search's thresholds stay in force. Returns C and the bound of the
/// result (certified by the minimiser's acceptance test).
#[allow(clippy::too_many_arguments)]
fn minimize_energy(
    s: &SplineSpace,
    mesh: &crate::mesh::LinearMesh,
    topo: &Topology,
    fit: &FitParams,
    options: &CurveOptions,
    params: &EnergyParams,
    certifier: &dyn Certifier,
    c_star: &[[f64; 3]],
    thresholds: &[f64],
    start: &[[f64; 3]],
) -> Result<(Vec<[f64; 3]>, EnergyInfo), EnergyError> {
    use crate::energy::{Energy, Validity, minimize_on};
    let energy = Energy::new(s, mesh, topo, fit, c_star, params)?;
    let depth = options.line_search.certificate_depth;
    let validity = Validity::for_start(&energy, certifier, depth, thresholds, start)?;
    let gpu = options.backend.gpu();
    let (mut c, info) = minimize_on(&energy, &validity, start, params, gpu, &mut |_| {})?;
    // The energy moves control points off the planes of planar patches; put them back where
    // the result stays accepted (it is a small move: the start was on the planes).
    if let Some(f) = &fit.features {
        let mut projected = c.clone();
        crate::fit::features::project_onto_planes(s, topo, f, &mut projected);
        if validity.accepts(&energy, &projected) {
            c = projected;
        }
    }
    Ok((c, info))
}

/// Rounds of demotion before giving up on an initially invalid spline map.
const MAX_DEMOTION_ROUNDS: usize = 16;

/// Mark `bad` elements for demotion; after the first round, or at once where a bad element is
/// Q2 already (demoting it again changes nothing), also every element sharing a vertex with
/// it, so repeated rounds grow a Q2 region around an area the spline cannot follow. (Growing by
/// facet neighbours only never frees a Q2 element constrained by spline neighbours across its
/// edges.)
fn demote_with_rings(
    mesh: &crate::mesh::LinearMesh,
    topo: &Topology,
    bad: &[usize],
    round: usize,
    is_q2: &dyn Fn(usize) -> bool,
    demote: &mut [bool],
) {
    for &e in bad {
        demote[e] = true;
        if round > 0 || is_q2(e) {
            for &v in mesh.element(e) {
                for &n in topo.elements_at_vertex(v as usize) {
                    demote[n as usize] = true;
                }
            }
        }
    }
}

/// Per-element acceptance threshold of the line search: `fraction` × the smallest corner det J
/// of the straight input element, but never more than half of what the initial map is
/// certified to achieve (0 where the initial map is not certified). `certify(target)` certifies
/// the initial map; its bounds need to be exact only where they are at most `target(e)` =
/// 2 × `fraction` × reference, since above that the threshold is `fraction` × reference.
fn acceptance_thresholds(
    mesh: &crate::mesh::LinearMesh,
    fraction: f64,
    certify: impl FnOnce(&(dyn Fn(usize) -> f64 + Sync)) -> Vec<crate::validity::DetBounds>,
) -> Vec<f64> {
    use rayon::prelude::*;
    if fraction <= 0.0 {
        return Vec::new();
    }
    let npe = mesh.nodes_per_element();
    let reference: Vec<f64> = (0..mesh.n_elements())
        .into_par_iter()
        .map(|e| {
            let x = mesh.element_coords(e);
            let mut jac = [0.0; 8];
            let mut scaled = [0.0; 8];
            crate::mesh::linear::corner_jacobians(
                mesh.dim,
                &x[..npe],
                &mut jac[..npe],
                &mut scaled[..npe],
            );
            jac[..npe]
                .iter()
                .copied()
                .fold(f64::INFINITY, f64::min)
                .max(0.0)
        })
        .collect();
    let initial = certify(&|e| 2.0 * (fraction * reference[e]));
    reference
        .par_iter()
        .zip(&initial)
        .map(|(&reference, initial)| {
            let initial = initial.lower;
            if initial > 0.0 {
                (fraction * reference).min(0.5 * initial)
            } else {
                0.0
            }
        })
        .collect()
}

/// Rounds of undoing snaps around elements that lose their certificate.
const MAX_SNAP_ROUNDS: usize = 8;

/// Move the output's boundary vertex nodes (node ids = input vertex ids) onto the input
/// vertices (paper §3), keeping only the moves after which every element containing a moved
/// node is still certified valid (det J of its Lagrange map, in Bernstein form). Returns the
/// number of vertices that really moved (not those already on their input vertex); edge and
/// face nodes are never moved.
pub fn snap_boundary(
    mesh: &crate::mesh::LinearMesh,
    topo: &Topology,
    ho: &mut HighOrderMesh,
    depth: usize,
) -> usize {
    use rayon::prelude::*;
    let nv = mesh.n_vertices();
    let original: Vec<[f64; 3]> = ho.nodes[..nv].to_vec();
    let mut snapped = topo.vertex_on_boundary.clone();
    for v in 0..nv {
        if snapped[v] {
            ho.nodes[v] = mesh.coords[v];
        }
    }
    let corner_ids = |ho: &HighOrderMesh, e: usize| -> Vec<u32> {
        ho.element(e)
            .iter()
            .copied()
            .filter(|&n| (n as usize) < nv)
            .collect()
    };
    let mut affected: Vec<usize> = (0..ho.n_elements())
        .filter(|&e| corner_ids(ho, e).iter().any(|&n| snapped[n as usize]))
        .collect();
    for round in 0..=MAX_SNAP_ROUNDS {
        let bad: Vec<usize> = affected
            .par_iter()
            .copied()
            .filter(|&e| !lagrange_element_bounds(ho, e, depth).certified_positive())
            .collect();
        if bad.is_empty() {
            break;
        }
        // Undo the snaps of the failing elements (all of them in the last round).
        for &e in &bad {
            for n in corner_ids(ho, e) {
                let n = n as usize;
                if snapped[n] {
                    snapped[n] = false;
                    ho.nodes[n] = original[n];
                }
            }
        }
        if round == MAX_SNAP_ROUNDS {
            for (n, s) in snapped.iter_mut().enumerate() {
                if *s {
                    *s = false;
                    ho.nodes[n] = original[n];
                }
            }
        }
        affected = bad;
    }
    (0..nv)
        .filter(|&n| snapped[n] && original[n] != mesh.coords[n])
        .count()
}
