//! The `curve` job's report ([`CurveReport`]): what was done, the certificate, quality and
//! boundary figures, and the seconds per [`crate::progress::Stage`]; assembled once, from the
//! stages' outcomes, at the end of the job.
//!
//! Input: the stages' outcomes over the whole mesh ([`Outcomes`]), the options and the stage
//! clock's timings. Output: the report. [`CurveReport::build`] is the one place a report is
//! made, at the end of the job's one tail (`pipeline::tail::finish_job`): the serial job gathers
//! its outcomes in [`CurveReport::outcomes`], the distributed job (`distributed::job`) sums and
//! reduces its ranks' shares into the same [`Outcomes`] and adds the fields that exist only
//! under mpirun (`ranks`, `per_rank`). Invariant: a field derived
//! from the options is written the same way for both, so an option or a figure is added once.

use super::spline::{SplineOutcome, SplineSetup};
use super::{CurveOptions, Geometry, Job};
use crate::deviation::BoundaryDeviation;
use crate::elastic::ElasticInfo;
use crate::energy::EnergyInfo;
use crate::exec::gpu::{AdapterReport, GpuTraffic, Precision};
use crate::fit::{FitSolver, FitTargets, FitWeights};
use crate::mesh::HighOrderMesh;
use crate::mesh::features::FeatureReport;
use crate::solve::CgInfo;
use crate::spline::{ElementClass, KnotIntervals, KnotSurfaceInfo, Q2Reason};
use crate::validity::LineSearchInfo;
use crate::validity::LineSearchMode;
use crate::validity::blend::BlendInfo;
use serde::Serialize;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// What `curve` did, for `--report` and the terminal.
///
/// Its JSON form is a contract, documented field by field in `docs/curve-report.schema.json`
/// (the `report_schema` integration test holds the two together). Distances called relative
/// are relative to `bounding_box_diagonal`.
#[deny(missing_docs)]
#[derive(Clone, Debug, Serialize)]
pub struct CurveReport {
    /// The input mesh file, as given.
    pub input: PathBuf,
    /// The written output file.
    pub output: PathBuf,
    /// 2 (quadrilaterals) or 3 (hexahedra).
    pub dimension: usize,
    /// Elements of the input mesh.
    pub elements: usize,
    /// Order of the output's Lagrange elements.
    pub order: usize,
    /// With `--subdivide K` (order 1 output): each element split into K^d linear elements.
    pub subdivide: Option<usize>,
    /// What was sampled: straight elements, the initial or the fitted spline map.
    pub geometry: Geometry,
    /// `iga` or `elastic`.
    pub method: &'static str,
    /// The elastic solve, with `--method elastic`.
    pub elastic: Option<ElasticInfo>,
    /// Nodes of the written mesh.
    pub output_nodes: usize,
    /// Elements of the written mesh.
    pub output_elements: usize,
    /// Boundary facets (edges in 2D, faces in 3D) of the written mesh.
    pub boundary_facets: usize,
    /// Control points of the spline space (0 with `--straight`).
    pub control_points: usize,
    /// Elements whose map is a spline element.
    pub spline_elements: usize,
    /// Elements with a constrained Q2 map (irregular neighbourhoods, demoted or kink elements).
    pub q2_elements: usize,
    /// Knot intervals of the spline space, `uniform` or `graded` (spline geometries).
    pub knot_intervals: Option<crate::spline::KnotIntervals>,
    /// Spline passes (space, fit, certified blend) run to choose the knots: 1, or 2 where
    /// `--knot-intervals auto` tried uniform and graded knots (spline geometries).
    pub knot_passes: Option<usize>,
    /// With graded knot intervals: the figures of the knot surfaces (surfaces, graded ones,
    /// non-orientable ones given uniform knots, clamped ratios, the largest |ln ratio|).
    pub knot_surfaces: Option<crate::spline::KnotSurfaceInfo>,
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
    /// Solver of the fit: `cg`, or `cholesky` (then `cg_iterations` is 0 and
    /// `cg_rel_residual` the factorisation's measured residual).
    pub fit_solver: Option<crate::fit::FitSolver>,
    /// CG iterations of the fit's solve (0 with Cholesky).
    pub cg_iterations: Option<usize>,
    /// Stored entries of the normal-equation matrix (one matrix for x, y, z).
    pub matrix_nonzeros: Option<usize>,
    /// Relative residual of the fit's solve.
    pub cg_rel_residual: Option<f64>,
    /// Where the fit's coupled solve ran, when the least-squares fit couples the coordinates
    /// across rotation seams (its system K ⊗ I₃ + C, `fit::rotated`; absent otherwise): `gpu`
    /// under `--backend gpu` (the device's coupled CG, `exec::gpu::cg::pcg_coupled`), `cpu`
    /// on the CPU backend, with `--fit-solver cholesky` (K's factor preconditions it on the
    /// CPU) and under mpirun (the ranks' fit runs on the CPU).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub coupled_fit_device: Option<&'static str>,
    /// What preconditioned that coupled CG (present with `coupled_fit_device`): K's factor
    /// (`cholesky`), K's block-Jacobi pair (`block-jacobi-pair`, on the CPU and the ranks) or
    /// K's diagonal (`jacobi`, on a device), whatever `--cg-preconditioner` (which applies to
    /// the uncoupled fit) says.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub coupled_fit_preconditioner: Option<&'static str>,
    /// What lowering the fitted map's kinks at C⁰ facets did in the last fit
    /// (`--facet-smoothing`, [`crate::fit::jumps`]); `None` when it did not run.
    pub facet_jumps: Option<crate::fit::jumps::JumpInfo>,
    /// `--line-search`: one step for the whole mesh or one per control point.
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
    /// The global line search's outcome (`--fit energy --line-search global`).
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
    /// Minimum scaled Jacobian of the input (at element corners).
    pub input_min_scaled_jacobian: f64,
    /// Minimum scaled Jacobian of the output (sampled).
    pub min_scaled_jacobian: f64,
    /// Bounding-box diagonal of the input: the `boundary_*` distances below are relative to it.
    pub bounding_box_diagonal: f64,
    /// Distance of the output's boundary vertex nodes from the input's boundary vertices
    /// (0 where `--snap-boundary` snapped them): the largest.
    pub boundary_vertex_deviation_max: f64,
    /// The same distances' root mean square.
    pub boundary_vertex_deviation_rms: f64,
    /// Largest distance of any written boundary node (vertex, edge or face node) from the
    /// input's linear boundary: how far the curving moved the wall ([`crate::deviation`]).
    pub boundary_node_distance_max: f64,
    /// The same over the output's boundary facets sampled on the lattice of order 2p.
    pub boundary_sample_distance_max: f64,
    /// With `--periodic`: the pairs, their transforms and the largest mismatch written.
    pub periodic: Option<PeriodicReport>,
    /// Seconds per stage, and `total`.
    pub timings: BTreeMap<String, f64>,
    /// `cpu` or `gpu`: where the heavy kernels ran.
    pub backend: String,
    /// With `gpu`: the adapter in use.
    pub adapter: Option<AdapterReport>,
    /// With `gpu`: the kernels' floating-point type.
    pub gpu_precision: Option<Precision>,
    /// With `gpu`: batches of work the device failed and the CPU did instead (the result is
    /// the same certified one; above 0, the device is unreliable or short of memory here).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub gpu_fallbacks: Option<usize>,
    /// With `gpu` only (absent otherwise): what each stage moved between host and device and
    /// through device memory, and the dispatches, submits and read-backs it issued, counted by
    /// the device context, under the keys of `timings` (every stage run; the fit's traffic is
    /// its CG's and, where K's values are summed on the device, its assembly's; the matrix's
    /// structure is built on the CPU). `write` runs after the report and moves nothing.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub gpu_traffic: Option<BTreeMap<String, GpuTraffic>>,
    /// Under mpirun only (absent otherwise): the number of ranks.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub ranks: Option<usize>,
    /// Under mpirun only (absent otherwise): each rank's share of the work.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub per_rank: Option<Vec<RankFigures>>,
}

/// One rank's share of the work and of the communication (the report's `per_rank`, under
/// mpirun).
#[deny(missing_docs)]
#[derive(Clone, Debug, Default, Serialize)]
pub struct RankFigures {
    /// The rank.
    pub rank: usize,
    /// Elements this rank assembles, certifies and sends.
    pub elements: usize,
    /// Ghost elements it read and built its setup on besides its own.
    pub ghost_elements: usize,
    /// Control points its elements touch (the rows it holds).
    pub control_points: usize,
    /// Control points it owns (counted in dot products).
    pub owned_control_points: usize,
    /// Control points it shares with other ranks (its halo).
    pub shared_control_points: usize,
    /// Ranks it exchanges halo values with.
    pub neighbours: usize,
    /// Stored entries of its share of K (local numbering).
    pub matrix_nonzeros: usize,
    /// Bytes it sent in all (halo exchanges, reductions, gathers).
    pub bytes_sent: u64,
    /// Bytes sent by the fit (CG halo exchanges and reductions).
    pub bytes_fit: u64,
    /// Bytes sent by the certified blend (rejected elements, counts).
    pub bytes_validity: u64,
    /// Bytes sent by the sampling (node tags and positions asked of and sent to their owners).
    pub bytes_gather: u64,
    /// Peak resident memory of the process (VmHWM), bytes, before the write.
    pub peak_memory_bytes: u64,
    /// The peak (VmHWM) at the end of each stage: the stage that raised it is where the
    /// memory is spent.
    pub peak_memory_by_stage: BTreeMap<String, u64>,
    /// Seconds per stage, under the keys of the report's `timings`.
    pub timings: BTreeMap<String, f64>,
}

/// The stages' outcomes over the whole mesh: everything [`CurveReport::build`] reads besides
/// the options and the timings.
pub(crate) struct Outcomes {
    /// 2 or 3.
    pub dimension: usize,
    /// Elements of the input mesh.
    pub elements: usize,
    /// Order of the output's elements.
    pub order: usize,
    /// Nodes, elements and boundary facets of the output.
    pub output_nodes: usize,
    pub output_elements: usize,
    pub boundary_facets: usize,
    /// The spline geometry's figures (`None` with `--straight`).
    pub spline: Option<SplineFigures>,
    pub snapped: Option<usize>,
    /// The elastic solve and the certified bound of its mesh.
    pub elastic: Option<(ElasticInfo, f64)>,
    /// The periodic seams' bound, folded into `min_det_jacobian_bound`, and their report.
    pub periodic: Option<(f64, PeriodicReport)>,
    pub input_min_scaled_jacobian: f64,
    pub min_scaled_jacobian: f64,
    /// Boundary distances relative to the diagonal, and the diagonal.
    pub deviation: BoundaryDeviation,
    /// The GPU in use: adapter, precision and fallbacks.
    pub gpu: Option<(AdapterReport, Precision, usize)>,
    /// Under mpirun: every rank's figures.
    pub per_rank: Option<Vec<RankFigures>>,
}

/// The spline geometry's figures over the whole mesh: the space's counts, the features, the
/// fit and the certified search (the report's fields of the same names).
pub(crate) struct SplineFigures {
    pub space: SpaceCounts,
    pub knot_surfaces: Option<KnotSurfaceInfo>,
    /// The fit's solver, its CG figures and the stored entries of its matrix.
    pub fit: Option<(FitSolver, CgInfo, usize)>,
    /// How the fit's coupled solve across rotation seams ran; `None` when the fit does not
    /// couple the coordinates.
    pub coupled: Option<crate::fit::CoupledRun>,
    /// What lowering the kinks at C⁰ facets did ([`crate::fit::jumps`]).
    pub facet_jumps: Option<crate::fit::jumps::JumpInfo>,
    pub demoted: usize,
    pub alpha: Option<f64>,
    pub invalid_at_full_step: usize,
    pub damped_points: usize,
    pub line_search: Option<LineSearchInfo>,
    pub blend: Option<BlendInfo>,
    pub energy: Option<EnergyInfo>,
    pub energy_skipped: Option<String>,
    pub min_det_bound: Option<f64>,
}

impl SplineFigures {
    /// The figures of a blended least-squares fit: the search's are the blend's (as the serial
    /// job's outcome of the same path), the blend's reduced points counted as held back.
    pub(crate) fn blended(
        space: SpaceCounts,
        fit: (FitSolver, CgInfo, usize),
        blend: BlendInfo,
    ) -> Self {
        SplineFigures {
            space,
            knot_surfaces: None,
            fit: Some(fit),
            coupled: None,
            facet_jumps: None,
            demoted: 0,
            alpha: Some(0.5 * blend.min_factor),
            invalid_at_full_step: blend.invalid_at_full_step,
            damped_points: blend.reduced_points,
            line_search: None,
            min_det_bound: Some(blend.min_det_lower_bound),
            blend: Some(blend),
            energy: None,
            energy_skipped: None,
        }
    }
}

/// The counts of a spline space over the whole mesh, its knots and its features.
pub(crate) struct SpaceCounts {
    pub control_points: usize,
    pub spline_elements: usize,
    pub q2_elements: usize,
    pub kink_elements: usize,
    pub knot_intervals: KnotIntervals,
    /// Spline passes run to choose the knots (the report's `knot_passes`).
    pub knot_passes: usize,
    /// The extraordinary midpoint weight of the fit kept (0 where its refit was not kept:
    /// `pipeline::passes::spline_passes`).
    pub extraordinary_midpoint: f64,
    /// Deviations relative to the diagonal.
    pub features: Option<FeatureReport>,
}

/// The outcomes of the serial job's stages that follow sampling (`--snap-boundary`, the
/// elastic analogy, periodic seams).
#[derive(Default)]
pub(super) struct Finished {
    pub snapped: Option<usize>,
    /// The elastic solve and the certified bound of its mesh.
    pub elastic: Option<(ElasticInfo, f64)>,
    /// The periodic pairs and what making the seams exact images did.
    pub periodic: Option<(
        Vec<crate::mesh::periodic::PeriodicPair>,
        crate::mesh::periodic::ImageInfo,
    )>,
}

/// The periodic seams of the written mesh (`--periodic`). Distances are relative to the
/// bounding-box diagonal.
#[deny(missing_docs)]
#[derive(Clone, Debug, Serialize)]
pub struct PeriodicReport {
    /// Each pair as used: sides, tags, transform, vertex pairs and input mismatch.
    pub pairs: Vec<crate::mesh::periodic::PeriodicSummary>,
    /// Node pairs written (every node of an image side paired with one of its master side).
    pub node_pairs: usize,
    /// Largest move of a seam node that made the image sides exact images.
    pub max_seam_shift: f64,
    /// Largest |T(x_master) − x_image| over the written node pairs.
    pub written_mismatch: f64,
    /// Elements certified again because a node of theirs moved (all passed; their bounds are
    /// in `min_det_jacobian_bound`).
    pub recertified_elements: usize,
    /// `c1`: every pair is identified in the spline space, so the curved map is C¹ across the
    /// seams where the elements are regular; `c0`: some pair is curved on each side and made
    /// exact images after sampling only.
    pub seam: &'static str,
    /// Why the seams are `c0`, when they are.
    pub seam_c0_reason: Option<String>,
    /// Whether the groups were written under PyFR's names `periodic_<i>_l` / `periodic_<i>_r`.
    pub pyfr_names: bool,
}

impl CurveReport {
    /// The serial `job`'s outcomes: its spline, its output `ho` with the stages after
    /// sampling `done`, its sampled `quality` and the input's smallest scaled Jacobian (the
    /// job's head's, [`super::head::Reduction::input_min_scaled_jacobian`]).
    pub(super) fn outcomes(
        job: &Job,
        spline: Option<&(SplineSetup, SplineOutcome)>,
        ho: &HighOrderMesh,
        done: &Finished,
        (min_scaled_jacobian, deviation): (f64, BoundaryDeviation),
        input_min_scaled_jacobian: f64,
    ) -> Outcomes {
        let (mesh, options) = (job.mesh, job.options);
        let setup = spline.map(|(setup, _)| setup);
        let figures = spline.map(|(setup, o)| {
            let space = &o.space;
            SplineFigures {
                space: SpaceCounts {
                    control_points: space.n_control_points(),
                    spline_elements: space.n_spline_elements(),
                    q2_elements: space.n_q2_elements(),
                    // Counted in the built space: elements Q2 for other reasons already are
                    // not kinks'.
                    kink_elements: space
                        .classes
                        .iter()
                        .filter(|c| **c == ElementClass::Q2(Q2Reason::BoundaryKink))
                        .count(),
                    knot_intervals: setup.knot_intervals,
                    knot_passes: setup.knot_passes,
                    extraordinary_midpoint: setup.fit_params.weights.extraordinary_midpoint,
                    features: setup.features.as_ref().map(|f| {
                        let (vertex, planarity) = f.deviations(mesh, ho, setup.boundary_rows());
                        FeatureReport {
                            found: f.summary(&options.features.params, setup.topo(job)),
                            feature_vertex_deviation_max: vertex,
                            planarity_max: planarity,
                        }
                    }),
                },
                knot_surfaces: (setup.knot_intervals == KnotIntervals::Graded)
                    .then_some(setup.knot_info),
                fit: o.fit.as_ref().map(|f| (f.solver, f.cg, f.nonzeros)),
                coupled: o.fit.as_ref().and_then(|f| f.coupled),
                facet_jumps: o.fit.as_ref().and_then(|f| f.facet_jumps),
                demoted: o.demoted,
                alpha: o.alpha,
                invalid_at_full_step: o.invalid_at_full_step,
                damped_points: o.damped_points,
                line_search: o.line_search.clone(),
                blend: o.blend.clone(),
                energy: o.energy.clone(),
                energy_skipped: o.energy_skipped.clone(),
                min_det_bound: o.min_det_bound,
            }
        });
        let periodic = done.periodic.as_ref().map(|(pairs, info)| {
            let diagonal = deviation.diagonal;
            let report = PeriodicReport {
                pairs: pairs.iter().map(|p| p.summary(diagonal)).collect(),
                node_pairs: ho.periodic.iter().map(|l| l.node_pairs.len()).sum(),
                max_seam_shift: info.max_shift / diagonal,
                written_mismatch: info.max_mismatch / diagonal,
                recertified_elements: info.recertified,
                seam: setup.map_or("c0", |s| s.seam_continuity().0),
                seam_c0_reason: match setup {
                    Some(s) => s.seam_continuity().1,
                    None => Some("straight-sided output".into()),
                },
                pyfr_names: options.periodic.pyfr_names,
            };
            (info.min_det_bound, report)
        });
        let gpu = job
            .executor
            .gpu()
            .map(|g| (g.adapter.clone(), g.precision, job.executor.fallbacks()));
        Outcomes {
            dimension: mesh.dim,
            elements: mesh.n_elements(),
            order: ho.order,
            output_nodes: ho.nodes.len(),
            output_elements: ho.n_elements(),
            boundary_facets: ho.n_boundary(),
            spline: figures,
            snapped: done.snapped,
            elastic: done.elastic,
            periodic,
            input_min_scaled_jacobian,
            min_scaled_jacobian,
            deviation,
            gpu,
            per_rank: None,
        }
    }

    /// The report of the output written to `output`: its path, the seconds of
    /// [`crate::progress::Stage::Write`] since `write_started` and of the whole job since
    /// `started` (`total`).
    pub(crate) fn written(&mut self, output: &Path, write_started: Instant, started: Instant) {
        use crate::progress::Stage;
        self.output = output.to_owned();
        let timings = &mut self.timings;
        timings.insert(
            Stage::Write.key().into(),
            write_started.elapsed().as_secs_f64(),
        );
        timings.insert(Stage::Total.key().into(), started.elapsed().as_secs_f64());
    }

    /// The report of the `curve` job on `input` with `options` from its stages' outcomes over
    /// the whole mesh and the stage clock's `timings` (`output` empty: set when written).
    pub(crate) fn build(
        input: &Path,
        options: &CurveOptions,
        o: Outcomes,
        timings: BTreeMap<String, f64>,
    ) -> CurveReport {
        let spline = o.spline.as_ref();
        let fit = spline.and_then(|s| s.fit);
        let coupled = spline.filter(|s| s.fit.is_some()).and_then(|s| s.coupled);
        let blend = spline.and_then(|s| s.blend.clone());
        CurveReport {
            input: input.to_owned(),
            output: PathBuf::new(),
            dimension: o.dimension,
            elements: o.elements,
            order: o.order,
            subdivide: options.subdivide,
            geometry: options.geometry,
            method: options.method.name(),
            elastic: o.elastic.map(|(info, _)| info),
            output_nodes: o.output_nodes,
            output_elements: o.output_elements,
            boundary_facets: o.boundary_facets,
            control_points: spline.map_or(0, |s| s.space.control_points),
            spline_elements: spline.map_or(0, |s| s.space.spline_elements),
            q2_elements: spline.map_or(0, |s| s.space.q2_elements),
            knot_intervals: spline.map(|s| s.space.knot_intervals),
            knot_passes: spline.map(|s| s.space.knot_passes),
            knot_surfaces: spline.and_then(|s| s.knot_surfaces),
            demoted_elements: spline.map_or(0, |s| s.demoted),
            kink_elements: spline.map_or(0, |s| s.space.kink_elements),
            snapped_boundary_vertices: o.snapped,
            features: spline.and_then(|s| s.space.features),
            fit_weights: fit.map(|_| {
                let graded = spline.map(|s| s.space.knot_intervals) == Some(KnotIntervals::Graded);
                let mut w = options.fit.weights.for_knots(graded);
                if let Some(s) = spline {
                    w.extraordinary_midpoint = s.space.extraordinary_midpoint;
                }
                w
            }),
            fit_targets: fit.map(|_| options.fit.targets),
            fit_solver: fit.map(|f| f.0),
            cg_iterations: fit.map(|f| f.1.iterations),
            matrix_nonzeros: fit.map(|f| f.2),
            cg_rel_residual: fit.map(|f| f.1.rel_residual),
            coupled_fit_device: coupled.map(|c| c.device),
            coupled_fit_preconditioner: coupled.map(|c| c.preconditioner.name()),
            facet_jumps: spline.and_then(|s| s.facet_jumps),
            line_search_mode: options.line_search_mode,
            line_search_alpha: spline.and_then(|s| s.alpha),
            invalid_at_full_step: spline.map_or(0, |s| s.invalid_at_full_step),
            damped_control_points: spline.map_or(0, |s| s.damped_points),
            line_search: spline.and_then(|s| s.line_search.clone()),
            reduced_elements: blend.as_ref().map_or(0, |b| b.reduced_elements),
            blend,
            energy: spline.and_then(|s| s.energy.clone()),
            energy_skipped: spline.and_then(|s| s.energy_skipped.clone()),
            invalid_elements: 0,
            // The elastic mesh replaces the spline's: its own certificate's bound.
            // The periodic seams' re-certified elements' bounds are folded in (a lower bound
            // of the whole mesh either way).
            min_det_jacobian_bound: match &o.elastic {
                Some((_, bound)) => Some(*bound),
                None => spline.and_then(|s| s.min_det_bound),
            }
            .map(|b| match &o.periodic {
                Some((bound, _)) => b.min(*bound),
                None => b,
            }),
            input_min_scaled_jacobian: o.input_min_scaled_jacobian,
            min_scaled_jacobian: o.min_scaled_jacobian,
            bounding_box_diagonal: o.deviation.diagonal,
            boundary_vertex_deviation_max: o.deviation.vertex_max,
            boundary_vertex_deviation_rms: o.deviation.vertex_rms,
            boundary_node_distance_max: o.deviation.node_max,
            boundary_sample_distance_max: o.deviation.sample_max,
            periodic: o.periodic.map(|(_, report)| report),
            timings,
            backend: options.backend.name().into(),
            adapter: o.gpu.as_ref().map(|g| g.0.clone()),
            gpu_precision: o.gpu.as_ref().map(|g| g.1),
            gpu_fallbacks: o.gpu.as_ref().map(|g| g.2),
            // Set by the serial job from its clock (the distributed job has no GPU path).
            gpu_traffic: None,
            ranks: o.per_rank.as_ref().map(Vec::len),
            per_rank: o.per_rank,
        }
    }
}
