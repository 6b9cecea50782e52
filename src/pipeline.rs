//! The `curve` job in stages, with timings and progress.
//!
//! Input: a mesh path and [`CurveOptions`]. Output: the written high-order mesh file and a
//! [`CurveReport`]. The output file is written atomically and never onto the input.
//! [`curve_in_memory`] is the same job without writing (used by `compare`), and
//! [`curve_raw_in_memory_with_progress`] the same on a mesh parsed elsewhere (the Python
//! package's arrays). The receiver of progress may stop the job between stages
//! ([`Progress::cancelled`]).
//!
//! The stages ([`Stage`]; each is one function returning a typed outcome, run by the stage clock
//! that times it and announces it to the [`Progress`] receiver):
//!
//! | stage | function | outcome |
//! |---|---|---|
//! | read | [`read_mesh`] | the [`LinearMesh`] |
//! | topology | `topology` | its [`Topology`], checked curvable |
//! | spline, fit, validity, energy | `spline::curve_spline` | the certified spline map (unless `--straight`) |
//! | sample | `sample_stage` | the order-P [`HighOrderMesh`] |
//! | snap | [`crate::validity::snap::snap_boundary`] | boundary vertex nodes moved back, still certified |
//! | elastic_sample, elastic, elastic_validity | `elastic_stage` | the elastic mesh, certified (`--method elastic`) |
//! | quality | `quality_stage` | sampled quality and boundary distances |
//! | write | [`crate::io::high_order::prepare_high_order`] | the output file |
//!
//! From sample on, the stages are the job's tail (`tail::finish_job`: sample, quality, the
//! report from the outcomes), one sequence for the serial job (`WholeJob`) and a rank under
//! mpirun over a `tail::JobShare`.
//!
//! Invariant: nothing is written unless every element is certified valid. With
//! [`Method::Elastic`] the spline is fitted and sampled as usual, then only its boundary nodes
//! are kept: the straight order-P mesh is moved onto them by linear elasticity
//! ([`crate::elastic`]) and each of its Lagrange elements must pass the det J certificate, or the
//! job fails with [`CurveError::Invalid`] and writes nothing.

pub(crate) mod clock;
pub(crate) mod head;
pub(crate) mod misfit;
mod options;
pub(crate) mod passes;
mod report;
pub(crate) mod share;
pub(crate) mod spline;
pub(crate) mod tail;

use crate::elastic::{ElasticError, ElasticInfo, ElasticParams, elastic_analogy_with_progress};
use crate::energy::EnergyError;
use crate::exec::Executor;
use crate::io::output::{PendingFile, WriteError};
use crate::io::{ReadError, read_mesh};
use crate::math::BezierElements;
use crate::mesh::HighOrderMesh;
use crate::mesh::raw::RawMesh;
use crate::mesh::{LinearMesh, Topology};
use crate::progress::{Progress, Silent, Stage};
use crate::quality::sample_det_jacobian;
use crate::sample::{MAX_ORDER, sample};
use crate::solve::CgError;
use crate::validity::ValidityError;
use crate::validity::blend::{BlendError, Blended};
use clock::Clock;
use head::{OneProcess, Reduction};
use report::Finished;
use spline::{SplineOutcome, SplineSetup};
use std::path::{Path, PathBuf};
use std::time::Instant;

pub use crate::io::high_order::{
    OutputFormat, OutputOptions, prepare_high_order, write_high_order,
};
pub use crate::validity::LineSearchMode;
pub use crate::validity::snap::snap_boundary;
pub use options::{CurveOptions, FeatureOptions, Geometry, Method, PeriodicOptions};
pub use report::{CurveReport, PeriodicReport, RankFigures};
pub(crate) use report::{Outcomes, SpaceCounts, SplineFigures};

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
        source: crate::exec::ExecutorError,
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
    /// A `--periodic` pair that names no boundary or whose sides are no images.
    #[error("{}: {source}", input.display())]
    Periodic {
        input: PathBuf,
        source: crate::mesh::periodic::PeriodicError,
    },
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
    /// The receiver of progress asked the job to stop ([`Progress::cancelled`]).
    #[error("interrupted; nothing was written")]
    Cancelled,
}

impl CurveError {
    /// The output would contain the elements `bad`, not certified valid: name the first few.
    pub(crate) fn invalid(input: &Path, what: &str, bad: &[usize]) -> CurveError {
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

/// A curved mesh in memory with the input it was made from (the `curve` job without writing).
pub struct Curved {
    pub mesh: LinearMesh,
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
    curve_with_progress(input, output, options, &Silent)
}

/// [`curve`], reporting stage progress to `progress`.
pub fn curve_with_progress(
    input: &Path,
    output: &Path,
    options: &CurveOptions,
    progress: &dyn Progress,
) -> Result<CurveReport, CurveError> {
    let (report, pending) = curve_prepared(input, output, options, progress)?;
    pending.commit()?;
    Ok(report)
}

/// [`curve_with_progress`] up to a complete, synced temporary of the output that
/// [`PendingFile::commit`] renames into place (dropped, it is removed): the caller can write
/// other outputs (the report) before either replaces its target.
pub fn curve_prepared(
    input: &Path,
    output: &Path,
    options: &CurveOptions,
    progress: &dyn Progress,
) -> Result<(CurveReport, PendingFile), CurveError> {
    OutputFormat::require(output)?;
    // Before any work: the output must not be the input and must be creatable.
    crate::io::output::check_outputs(&[output], &[input])?;
    let start = Instant::now();
    let Curved { ho, mut report, .. } = curve_in_memory_with_progress(input, options, progress)?;
    if progress.cancelled() {
        return Err(CurveError::Cancelled);
    }
    progress.started(Stage::Write);
    let t = Instant::now();
    let pending = prepare_high_order(&ho, output, &options.output, &[input])?;
    report.written(output, t, start);
    progress.finished(Stage::Write);
    Ok((report, pending))
}

/// Everything of the `curve` job but writing the output.
pub fn curve_in_memory(input: &Path, options: &CurveOptions) -> Result<Curved, CurveError> {
    curve_in_memory_with_progress(input, options, &Silent)
}

/// What every stage reads: the input, the options, the mesh and where the work runs.
pub(crate) struct Job<'a> {
    pub input: &'a Path,
    pub options: &'a CurveOptions,
    pub mesh: &'a LinearMesh,
    pub topo: &'a Topology,
    /// Where certification, the fit's CG, sampling and the energy's local derivatives run.
    pub executor: &'a dyn Executor,
}

/// [`curve_in_memory`], reporting stage progress to `progress`.
pub fn curve_in_memory_with_progress(
    input: &Path,
    options: &CurveOptions,
    progress: &dyn Progress,
) -> Result<Curved, CurveError> {
    curve_mesh(input, options, progress, || read_mesh(input, &options.mesh))
}

/// [`curve_in_memory_with_progress`] of a mesh already parsed (by a caller that reads its
/// own formats, or builds the mesh from arrays): `raw` is checked and oriented as a file's
/// would be ([`LinearMesh::from_raw`]), and `name` stands for the file in every message
/// (`<memory>`, for example). The report's `input` is `name`.
pub fn curve_raw_in_memory_with_progress(
    raw: RawMesh,
    name: &Path,
    options: &CurveOptions,
    progress: &dyn Progress,
) -> Result<Curved, CurveError> {
    curve_mesh(name, options, progress, || {
        LinearMesh::from_raw(raw, &options.mesh).map_err(|source| ReadError::Parse {
            path: name.to_owned(),
            source,
        })
    })
}

/// The job on the mesh `read` gives (its stage is [`Stage::Read`]).
fn curve_mesh(
    input: &Path,
    options: &CurveOptions,
    progress: &dyn Progress,
    read: impl FnOnce() -> Result<LinearMesh, ReadError>,
) -> Result<Curved, CurveError> {
    let (order, elastic) = check_options(options)?;
    let start = Instant::now();
    let mut clock = Clock::new(progress).counting(&options.backend);
    let mesh = clock.run(Stage::Read, read)?;
    clock.check()?;
    let (topo, input_msj) = clock.run(Stage::Topology, || {
        let topo = topology(input, &mesh)?;
        Ok::<_, CurveError>((topo, OneProcess.input_min_scaled_jacobian(&mesh)))
    })?;
    let periodic = clock
        .run(Stage::Topology, || {
            crate::mesh::periodic::resolve(&mesh, &topo, &options.periodic.pairs)
        })
        .map_err(|source| CurveError::Periodic {
            input: input.to_owned(),
            source,
        })?;
    head::check_pyfr_names(input, options.periodic.pyfr_names, &periodic)?;
    clock.check()?;
    let executor = crate::exec::executor(&options.backend);
    let job = Job {
        input,
        options,
        mesh: &mesh,
        topo: &topo,
        executor: executor.as_ref(),
    };
    let spline = match options.geometry {
        Geometry::Straight => None,
        _ => Some(spline::curve_spline(&job, &mut clock, &periodic)?),
    };
    let mut whole = WholeJob {
        job: &job,
        spline,
        order,
        elastic,
        periodic,
        input_msj,
        done: Finished::default(),
    };
    let (ho, report) = tail::finish_job(&mut whole, input, options, clock, start)?;
    Ok(Curved {
        mesh,
        topo,
        ho,
        report,
    })
}

/// The serial job's share of the tail ([`tail::JobShare`]): every element is its own.
struct WholeJob<'a> {
    job: &'a Job<'a>,
    spline: Option<(SplineSetup, SplineOutcome)>,
    order: usize,
    /// The elastic analogy's parameters with `--method elastic`.
    elastic: Option<ElasticParams>,
    /// The periodic pairs resolved on the input.
    periodic: Vec<crate::mesh::periodic::PeriodicPair>,
    /// The input's smallest scaled Jacobian.
    input_msj: f64,
    /// The outcomes of the stages after sampling.
    done: Finished,
}

impl tail::JobShare for WholeJob<'_> {
    type Output = HighOrderMesh;
    fn sample(&mut self, clock: &mut Clock) -> Result<HighOrderMesh, CurveError> {
        let (job, order) = (self.job, self.order);
        let mut ho = clock.run(Stage::Sample, || {
            sample_stage(job, self.spline.as_mut(), order, self.elastic.is_none())
        })?;
        clock.check()?;
        let options = job.options;
        self.done.snapped = options.snap_boundary.then(|| {
            let depth = options.line_search.certificate_depth;
            clock.run(Stage::Snap, || {
                snap_boundary(job.mesh, job.topo, &mut ho, depth)
            })
        });
        if let Some(params) = &self.elastic {
            let (moved, info, bound) = elastic_stage(job, clock, params, &ho, order)?;
            ho = moved;
            self.done.elastic = Some((info, bound));
        }
        if !self.periodic.is_empty() {
            let info = clock.run(Stage::Periodic, || {
                periodic_stage(job, &self.periodic, &mut ho, order)
            })?;
            self.done.periodic = Some((std::mem::take(&mut self.periodic), info));
        }
        Ok(ho)
    }
    fn quality(
        &mut self,
        ho: &HighOrderMesh,
    ) -> Result<(f64, crate::deviation::BoundaryDeviation), CurveError> {
        quality_stage(self.job, ho)
    }
    fn outcomes(
        &mut self,
        ho: &HighOrderMesh,
        quality: (f64, crate::deviation::BoundaryDeviation),
        _clock: &Clock,
    ) -> report::Outcomes {
        let spline = self.spline.as_ref();
        CurveReport::outcomes(self.job, spline, ho, &self.done, quality, self.input_msj)
    }
}

/// The options no stage can run with are refused before reading: the output order and the
/// elastic parameters when the method is elastic.
pub(crate) fn check_options(
    options: &CurveOptions,
) -> Result<(usize, Option<ElasticParams>), CurveError> {
    let order = options.subdivide.unwrap_or(options.order);
    if options.subdivide.is_some() && options.order != 1 {
        return Err(CurveError::Options(
            "--subdivide gives order-1 output; use it with --order 1".into(),
        ));
    }
    options
        .check()
        .map_err(|e| CurveError::Options(e.to_string()))?;
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
    Ok((order, elastic))
}

/// The topology of the input, which must be curvable (manifold, with a boundary).
pub(crate) fn topology(input: &Path, mesh: &LinearMesh) -> Result<Topology, CurveError> {
    let topo = Topology::build(mesh);
    crate::mesh::manifold::check_curvable(mesh, &topo).map_err(|what| CurveError::NotCurvable {
        input: input.to_owned(),
        what,
    })?;
    Ok(topo)
}

/// The order-P Lagrange nodes of the certified map: the blended fit, the spline map, or the
/// straight elements; split into order-1 sub-elements with `--subdivide` (after the elastic
/// analogy instead, when there is one: `subdivide_now` is false then).
fn sample_stage(
    job: &Job,
    spline: Option<&mut (SplineSetup, SplineOutcome)>,
    order: usize,
    subdivide_now: bool,
) -> Result<HighOrderMesh, CurveError> {
    let (mesh, topo) = (job.mesh, job.topo);
    let target_map;
    let blended;
    let source: &dyn BezierElements = match spline {
        Some((setup, outcome)) => match outcome.blend_factors.clone() {
            Some(factors) => {
                target_map = setup.target_map(job);
                // The search's nets: the reduced elements' target-map corrections once only.
                let nets = outcome.blend_nets.take();
                let space = &outcome.space;
                let (ids_mesh, ids_topo) = setup.entity_mesh(job);
                blended = match nets {
                    Some(c) => Blended::with_cache(
                        mesh,
                        &target_map,
                        space,
                        ids_mesh,
                        ids_topo,
                        factors,
                        c,
                    )
                    .with_geometry(mesh),
                    None => Blended::new(mesh, &target_map, space, ids_mesh, ids_topo, factors)
                        .with_geometry(mesh),
                };
                &blended
            }
            None => &outcome.space,
        },
        None => mesh,
    };
    let ho = job
        .executor
        .sample(source, mesh, topo, order)
        .map_err(|source| CurveError::Gpu {
            input: job.input.to_owned(),
            source,
        })?;
    if job.options.subdivide.is_some() && subdivide_now {
        Ok(ho.subdivided())
    } else {
        Ok(ho)
    }
}

/// The elastic analogy: the straight order-P mesh with its boundary moved onto the sampled
/// spline's boundary `ho`, every Lagrange element certified. Returns the mesh, the solve's
/// figures and the smallest certified bound.
fn elastic_stage(
    job: &Job,
    clock: &mut Clock,
    params: &ElasticParams,
    ho: &HighOrderMesh,
    order: usize,
) -> Result<(HighOrderMesh, ElasticInfo, f64), CurveError> {
    let (mesh, topo) = (job.mesh, job.topo);
    let straight = clock.run(Stage::ElasticSample, || sample(mesh, mesh, topo, order));
    // Every CG iteration reported and asked whether to stop, as the fit's.
    let progress = clock.progress();
    let mut monitor = crate::solve::Cancellable {
        progress: |i, r| progress.elastic_cg(i, r),
        cancelled: || progress.cancelled(),
    };
    let (moved, info) = clock
        .run(Stage::Elastic, || {
            elastic_analogy_with_progress(&straight, ho, params, &mut monitor)
        })
        .map_err(|source| match source {
            ElasticError::Solve(crate::solve::CgError::Cancelled { .. }) => CurveError::Cancelled,
            source => CurveError::Elastic {
                input: job.input.to_owned(),
                source,
            },
        })?;
    clock.add(Stage::ElasticAssembly, info.assembly_seconds);
    clock.add(Stage::ElasticCg, info.solve_seconds);
    let depth = job.options.line_search.certificate_depth;
    let mut moved = moved;
    let mut info = info;
    let bounds = clock.run(Stage::ElasticValidity, || {
        use rayon::prelude::*;
        let certify = |ho: &HighOrderMesh, e: usize| {
            crate::validity::lagrange_element_bounds(ho, e, depth).certified_positive()
        };
        let (_, held) = crate::elastic::hold_back_invalid(&straight, &mut moved, certify);
        info.held_back_nodes = held.nodes;
        info.held_back_boundary_nodes = held.boundary_nodes;
        info.min_displacement_fraction = held.min_fraction;
        (0..moved.n_elements())
            .into_par_iter()
            .map(|e| crate::validity::lagrange_element_bounds(&moved, e, depth))
            .collect::<Vec<_>>()
    });
    let bad = crate::validity::certificate::uncertified(&bounds);
    if !bad.is_empty() {
        return Err(CurveError::invalid(job.input, "elastic-analogy mesh", &bad));
    }
    let bound = bounds.iter().map(|b| b.lower).fold(f64::INFINITY, f64::min);
    let moved = match job.options.subdivide {
        Some(_) => moved.subdivided(),
        None => moved,
    };
    Ok((moved, info, bound))
}

/// Periodic seams: pair the order-P nodes of each pair's sides on the straight mesh of the
/// same order (the node numbering of every sampled mesh), move them so that the image side's
/// nodes are exactly the transform of the master side's, and certify every element that holds
/// a moved node ([`crate::mesh::periodic::make_images`]); nothing uncertified passes. With
/// `--periodic-pyfr-names` the groups are renamed `periodic_<i>_l` / `periodic_<i>_r`.
fn periodic_stage(
    job: &Job,
    pairs: &[crate::mesh::periodic::PeriodicPair],
    ho: &mut HighOrderMesh,
    order: usize,
) -> Result<crate::mesh::periodic::ImageInfo, CurveError> {
    let straight = sample(job.mesh, job.mesh, job.topo, order);
    let links = crate::mesh::periodic::node_pairs(&straight, pairs).map_err(|source| {
        CurveError::Periodic {
            input: job.input.to_owned(),
            source,
        }
    })?;
    let depth = job.options.line_search.certificate_depth;
    let (bad, info) = crate::mesh::periodic::make_images(ho, &links, |ho, e| {
        crate::validity::lagrange_element_bounds(ho, e, depth).lower
    });
    if !bad.is_empty() {
        return Err(CurveError::invalid(job.input, "periodic seam", &bad));
    }
    if job.options.periodic.pyfr_names {
        for (i, p) in pairs.iter().enumerate() {
            ho.tag_names.insert(p.master_tag, format!("periodic_{i}_l"));
            ho.tag_names.insert(p.slave_tag, format!("periodic_{i}_r"));
        }
    }
    ho.periodic = links;
    Ok(info)
}

/// The sampled quality of the output (every element must have det J > 0 on the lattice of
/// order 2P: a last check beyond the certificate) and its boundary distances from the input.
pub(crate) fn quality_stage(
    job: &Job,
    ho: &HighOrderMesh,
) -> Result<(f64, crate::deviation::BoundaryDeviation), CurveError> {
    let quality = sample_det_jacobian(ho);
    let min_sj = quality
        .iter()
        .map(|q| q.min_scaled_jacobian)
        .fold(f64::INFINITY, f64::min);
    let invalid: Vec<usize> = (0..quality.len())
        .filter(|&e| !(quality[e].min_det_jacobian > 0.0))
        .collect();
    if !invalid.is_empty() {
        return Err(CurveError::invalid(job.input, "sampled output", &invalid));
    }
    let deviation = crate::deviation::boundary_deviation(job.mesh, job.topo, ho);
    Ok((min_sj, deviation))
}

/// Distance of the output's vertex nodes on the boundary from the input's boundary vertices
/// (node ids of vertices equal the input vertex ids), relative to the bounding-box diagonal:
/// (max, rms). The report's other boundary measures are in [`crate::deviation`].
pub fn boundary_deviation(mesh: &LinearMesh, topo: &Topology, ho: &HighOrderMesh) -> (f64, f64) {
    crate::deviation::vertex_deviation(mesh, topo, ho)
}
