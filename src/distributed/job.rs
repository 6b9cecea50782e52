//! The `curve` job across MPI ranks (see `docs/distributed.md` for what is distributed and
//! what is not yet).
//!
//! Input: the input mesh path (binary MSH 4.1), [`CurveOptions`] (the default IGA path: the
//! certified blend of the least-squares fit, CPU backend) and a [`Comm`]. Output: on every
//! rank, its share of the sampled output in global node tags ([`RankOutput`], written
//! collectively by [`super::write`]) and the [`CurveReport`], the serial job's report made by
//! the same builder (`CurveReport::build`) from the ranks' outcomes summed and reduced, with
//! `ranks` and `per_rank` set. The stages run on the serial job's stage clock under the same
//! [`Stage`]s (and [`Stage::Partition`], the halo), so `timings` has the serial keys.
//!
//! Stages per rank: read its contiguous run of the file's elements by offsets, move the
//! elements to their Morton parts and read [`GHOST_DEPTH`] vertex rings of ghosts
//! ([`super::share`], [`super::read`]); build the topology on that sub-mesh (the entities
//! of its own elements checked); run the serial job's head (`pipeline::head`, over the
//! ranks' reduction: every stage that may fail on one rank agreed, the input's smallest
//! scaled Jacobian, the seams' gluing rule, then `spline_job`: the features, smooth targets
//! and spline space on that sub-mesh with the serial stage functions,
//! `pipeline::spline::SplineSetup`, and the serial job's spline passes,
//! `pipeline::passes::spline_passes`, one or two passes of what follows) with graded or
//! `auto` knots surveyed over the whole mesh, the serial knot weights taken
//! ([`super::knots`]) and `auto` deciding on the whole mesh's figures; each pass is the
//! serial pass's sequence (`pipeline::share::least_squares_pass`: space, fit, misfit rounds,
//! certified blend) over this rank's `Share` (`RankPasses`); agree on the shared
//! control points by keys of
//! global entity ids ([`super::local`]); assemble the normal equations over its own elements
//! with the whole mesh's size levels ([`crate::fit::partial`]); solve them with the
//! distributed CG ([`super::cg`]) under the serial preconditioner; run the certified blend on
//! its own elements, the ranks agreeing on the rejected elements of every round in global ids
//! ([`crate::validity::blend::blend_search_shared`]); sample its own elements with a global
//! node numbering ([`super::sample`]), with periodic pairs resolved over the whole mesh (the
//! seams glued in the spline space: the share read again with its ghost rings across the
//! seams; across rotation seams the CG couples the coordinates, [`super::cg::pcg_coupled`])
//! and the image sides' nodes made the transform of their masters'
//! ([`super::periodic`]),
//! check them and route them back to their file runs for the collective write (the serial
//! job's tail, `pipeline::tail::finish_job`: sample, quality, outcomes, over this rank's
//! `JobShare`, `RankJob`); no rank reads or holds the whole mesh.
//! Invariant: the result is the serial run's (the same knots too) up to the order of the
//! sums: the CG applies the serial preconditioner on the serial aggregates
//! ([`super::blocks`]), so it takes the serial iterates and stops where the serial solve
//! stops; the blend's factors are the serial search's for the same fitted map.

use super::blocks::Aggregation;
use super::cg::{Halo, LocalMatrix, pcg, pcg_coupled};
use super::comm::Comm;
use super::local::{GHOST_DEPTH, LocalShare};
use super::read::LocalMesh;
use super::sample::{RankOutput, sample_share};
use super::share::read_share;
use crate::mesh::Topology;
use crate::pipeline::clock::{Clock, peak_memory_bytes};
use crate::pipeline::head::{Reduce, Reduction, agreed, check_pyfr_names, spline_job};
use crate::pipeline::passes::Passes;
use crate::pipeline::share::{
    Blend, LeastSquares, Share, blend_within, finish_blend, least_squares_pass,
};
use crate::pipeline::spline::{Demoted, SplineSetup};
use crate::pipeline::tail::{JobShare, finish_job};
use crate::pipeline::{
    CurveError, CurveOptions, CurveReport, Geometry, Job, Method, Outcomes, RankFigures,
    SpaceCounts, SplineFigures,
};
use crate::progress::{Silent, Stage};
use crate::spline::{ElementClass, KnotIntervals, KnotParams, Knots, Q2Reason, SplineSpace};
use crate::validity::blend::Blended;
use std::collections::BTreeMap;
use std::path::Path;
use std::time::Instant;

/// What every rank holds at the end: its share of the output and the report (the same on
/// every rank).
pub struct Finished {
    pub output: RankOutput,
    /// The input's names of tags (the output's group names).
    pub tag_names: BTreeMap<i32, String>,
    pub report: CurveReport,
}

/// The options the distributed job runs; anything else is one bounded error line. Every
/// option is named here, none left to `..`: an option added to [`CurveOptions`] (or to the
/// fit's weights, solver or features) does not compile until this says whether the ranks run
/// it or refuse it, so none is ignored under mpirun. The output options are the collective
/// writer's (`launch::check_output`).
fn check_supported(options: &CurveOptions) -> Result<(), CurveError> {
    let unsupported = |what: &str| {
        Err(CurveError::Options(format!(
            "{what} is not available under mpirun yet (docs/distributed.md); run it on one process"
        )))
    };
    // `_`: the ranks run it as the serial job does (the same stage functions and checks).
    let CurveOptions {
        order: _,
        subdivide,
        geometry,
        method,
        fit,
        knots: _,
        line_search: _,
        line_search_mode: _,
        snap_boundary,
        demote_uncertified: _,
        features,
        mesh: _,
        output: _,
        backend,
        energy,
        periodic: _,
    } = options;
    let crate::fit::FitParams {
        weights,
        solver,
        cg,
        targets: _,
        features: _,
        facet_smoothing,
    } = fit;
    let crate::fit::FitWeights {
        corner: _,
        boundary_corner: _,
        midpoint: _,
        deep_midpoint,
        extraordinary_midpoint: _,
        boundary_midpoint: _,
        frame_corner: _,
        frame_midpoint: _,
        feature: _,
    } = weights;
    let crate::solve::CgParams {
        rel_tol: _,
        abs_tol: _,
        max_iters: _,
        preconditioner,
    } = cg;
    let crate::pipeline::FeatureOptions {
        params: _,
        edits,
        ignore: _,
    } = features;
    if *geometry != Geometry::SplineFitted {
        return unsupported("--straight or --fit none");
    }
    if energy.is_some() {
        return unsupported("--fit energy");
    }
    // One solve over the C⁰ facets of the whole mesh; the ranks' parts would each see a cut
    // (the command line's default under mpirun is 0).
    if *facet_smoothing > 0.0 {
        return unsupported("--facet-smoothing");
    }
    if !matches!(method, Method::Iga) {
        return unsupported("--method elastic");
    }
    if backend.gpu().is_some() {
        return unsupported("the GPU backend");
    }
    if subdivide.is_some() {
        return unsupported("--subdivide");
    }
    if *snap_boundary {
        return unsupported("--snap-boundary");
    }
    // The edits name vertices by their place in the file; a rank's sub-mesh numbers them
    // otherwise, so they would hit other vertices.
    if edits.is_some() {
        return unsupported("--feature-edits");
    }
    // The deep midpoints are found on the mesh a rank holds, whose cut fringe is not the
    // whole mesh's boundary.
    if deep_midpoint.is_some() {
        return unsupported("--w-deep-midpoint");
    }
    // The ranks solve by CG (`auto` means CG here); a factorisation of the whole system is
    // not distributed.
    if *solver == crate::fit::FitSolver::Cholesky {
        return unsupported("--fit-solver cholesky");
    }
    // The sweeps of block Gauss–Seidel run across the whole matrix in one order (the CG
    // refuses it too: `CgError::Unavailable`).
    if let crate::solve::CgPreconditioner::BlockSgs { .. } = preconditioner {
        return unsupported("--cg-preconditioner block-sgs");
    }
    // The lattice lines run through the whole mesh, across the ranks' shares.
    if let crate::solve::CgPreconditioner::BlockJacobiLines { .. } = preconditioner {
        return unsupported("--cg-preconditioner block-jacobi-lines");
    }
    Ok(())
}

/// A rank's share of the job's tail ([`JobShare`]): its own elements sampled in global node
/// tags, the quality reduced and its outcomes summed over the ranks.
struct RankJob<'a> {
    comm: &'a dyn Comm,
    local: &'a LocalMesh,
    job: &'a Job<'a>,
    setup: &'a SplineSetup,
    order: usize,
    /// The pass kept: its space, its fit's figures and its certified blend's factors and nets
    /// (taken when sampled).
    space: &'a SplineSpace,
    fit: &'a RankFit,
    cache: Option<(Vec<f32>, crate::validity::blend::NetCache)>,
    blend: crate::validity::blend::BlendInfo,
    /// Elements of the whole mesh demoted to Q2 before the fit (`--demote-uncertified`).
    demoted: usize,
    /// The input's smallest scaled Jacobian over the ranks.
    input_msj: f64,
    /// The periodic pairs (`--periodic`), resolved over the whole mesh.
    pairs: &'a [crate::mesh::periodic::PeriodicPair],
    /// Bytes sent by the fits, the blends and the sampling.
    bytes: [u64; 3],
    /// The whole mesh's feature summary (deviations absolute), when any rank found features.
    features: Option<crate::mesh::features::FeatureReport>,
    /// `c1` when the seams are glued in the spline space (on every rank alike), else `c0`
    /// with why ([`SplineSetup::seam_continuity`]).
    seam: (&'static str, Option<String>),
    /// Own control points (counted once over the ranks), spline, Q2 and kink elements, and
    /// the output's nodes and boundary facets, summed over the ranks.
    counts: [usize; 4],
    sizes: [u64; 2],
}

/// The topology of a ghosted sub-mesh, checked curvable where the serial check would see the
/// same thing: the non-manifold entities among the vertices of the own elements (the fringe of
/// the ghost layer is cut out of the mesh and may look non-manifold).
fn local_topology(input: &Path, local: &LocalMesh) -> Result<Topology, CurveError> {
    let mesh = &local.mesh;
    let topo = Topology::build(mesh);
    let mut near = vec![false; mesh.n_vertices()];
    for e in 0..local.n_owned {
        for &v in mesh.element(e) {
            near[v as usize] = true;
        }
    }
    let nm = &topo.non_manifold;
    let all_near = |vs: &[u32]| vs.iter().all(|&v| near[v as usize]);
    let facet = |f: u32| -> Vec<u32> {
        if topo.dim == 2 {
            topo.edges[f as usize].to_vec()
        } else {
            topo.faces[f as usize].to_vec()
        }
    };
    let bad = nm.facets.iter().filter(|&&f| all_near(&facet(f))).count()
        + nm.edges
            .iter()
            .filter(|&&d| all_near(&topo.edges[d as usize]))
            .count()
        + nm.vertices.iter().filter(|&&v| near[v as usize]).count();
    if bad > 0 {
        return Err(CurveError::NotCurvable {
            input: input.to_owned(),
            what: format!(
                "{bad} non-manifold facet(s), edge(s) or vertice(s) among the {} elements of rank {} (run it on one process for the details)",
                local.n_owned,
                local.owner.first().copied().unwrap_or(0)
            ),
        });
    }
    Ok(topo)
}

/// What every stage of a rank's share reads: the job's (on the sub-mesh), the communicator and
/// the sub-mesh's own elements.
struct ShareJob<'a> {
    comm: &'a dyn Comm,
    local: &'a LocalMesh,
    job: &'a Job<'a>,
    setup: &'a SplineSetup,
    mine: &'a [usize],
}

/// This rank's share of the fit, timed as [`Stage::Fit`] with its assembly and CG parts
/// ([`fit_share`]).
fn fit_stage(
    j: &ShareJob,
    clock: &mut Clock,
    s: &SplineSpace,
    halo: &Halo,
    start: Option<&[[f64; 3]]>,
) -> Result<Fitted, CurveError> {
    let t = Instant::now();
    let fit = fit_share(j, clock, s, halo, start);
    clock.add(Stage::Fit, t.elapsed().as_secs_f64());
    fit
}

/// This rank's share of the fit: its rows of the normal equations with the whole mesh's size
/// levels, the scaling agreed over the halo ([`Stage::FitAssembly`]), the distributed CG
/// with its preconditioner's aggregates grown first ([`Stage::FitCg`]). The CG starts from
/// the control points `start` where given (one per control point of `s`), as the serial
/// fit's warm start does ([`crate::fit::fit_with_targets_from`]). Returns the fitted control
/// points of `s` (projected onto planar patches; `s` keeps its own), the CG's figures and the
/// stored entries of the rank's local matrix and of the whole K
/// ([`LocalMatrix::global_nonzeros`]).
fn fit_share(
    j: &ShareJob,
    clock: &mut Clock,
    s: &SplineSpace,
    halo: &Halo,
    start: Option<&[[f64; 3]]>,
) -> Result<Fitted, CurveError> {
    // The boundary is fitted on the topology with the glued seams interior.
    let (comm, topo, setup) = (j.comm, j.setup.topo(j.job), j.setup);
    let fit_params = &setup.fit_params;
    // The preconditioner's aggregates (the serial run's: rank 0 grows them on the whole
    // mesh's stencils) before the assembly, while a rank holds least.
    // Across rotation seams the coordinates are coupled (`crate::fit::rotated`): every rank
    // runs the coupled CG when some rank's elements see a control point rotated.
    let mut rotated = [f64::from(u8::from(s.extraction.has_frames()))];
    comm.max_f64(&mut rotated);
    let coupled = rotated[0] > 0.0;
    // The coupled solve is preconditioned by K's block-Jacobi pair, as serially.
    let preconditioner = if coupled {
        crate::solve::CgPreconditioner::BlockJacobiPair {
            size: crate::solve::block_jacobi::DEFAULT_BLOCK,
        }
    } else {
        fit_params.cg.preconditioner
    };
    let aggregation = clock.run(Stage::FitCg, || {
        let stencils = super::blocks::own_stencils(s, halo, j.mine);
        Aggregation::for_preconditioner(comm, halo, &stencils, &preconditioner)
    });
    let (k, b, scale, coupling) = clock.run(Stage::FitAssembly, || assemble_share(j, s, halo));
    // The unknowns are displacements from the initial control points, scaled like K.
    let mut delta: Vec<[f64; 3]> = match start {
        Some(start) => halo
            .global
            .iter()
            .map(|&g| {
                let (g, c) = (g as usize, s.control_points[g as usize]);
                let d = scale.as_ref().map_or(1.0, |d| d[g]);
                std::array::from_fn(|a| (start[g][a] - c[a]) / d)
            })
            .collect(),
        None => vec![[0.0; 3]; halo.len()],
    };
    if start.is_some() {
        clock.run(Stage::FitCg, || {
            super::cg::keep_closer_starts(comm, halo, &k, &b, &mut delta)
        });
    }
    // Where the serial fit factors K (the whole mesh's size: every rank decides alike) the
    // ranks' CG runs to the factorisation's accuracy (`crate::fit::FitSolver::cg_params`),
    // as the serial coupled CG across rotation seams does, and gives the direct solution:
    // stopped at `--cg-tol`, the 189-hex generated torus differed from the serial output by
    // 2.7e-6 of the diagonal.
    let mut unknowns = [halo.owned.iter().filter(|&&o| o).count() as u64];
    comm.sum_u64(&mut unknowns);
    let cg_params = fit_params
        .solver
        .cg_params(s.dim, unknowns[0] as usize, &fit_params.cg);
    let cg = clock
        .run(Stage::FitCg, || {
            if coupled {
                pcg_coupled(
                    comm,
                    halo,
                    &k,
                    coupling.as_ref(),
                    &b,
                    &mut delta,
                    &cg_params,
                    aggregation.as_ref(),
                )
            } else {
                pcg(
                    comm,
                    halo,
                    &k,
                    &b,
                    &mut delta,
                    &cg_params,
                    aggregation.as_ref(),
                )
            }
        })
        .map_err(|source| CurveError::Solve {
            input: j.job.input.to_owned(),
            source,
        })?;
    let mut c_star = s.control_points.clone();
    for (i, &g) in halo.global.iter().enumerate() {
        let g = g as usize;
        let d = scale.as_ref().map_or(1.0, |d| d[g]);
        for c in 0..3 {
            c_star[g][c] += d * delta[i][c];
        }
    }
    if let Some(f) = setup.used_features() {
        crate::fit::features::project_onto_planes(s, topo, f, &mut c_star);
    }
    Ok((c_star, cg, [k.nonzeros(), k.global_nonzeros(comm, halo)]))
}

/// The fitted control points, the CG's figures and the stored entries of the rank's share of
/// K and of the whole K ([`fit_share`]).
type Fitted = (Vec<[f64; 3]>, crate::solve::CgInfo, [usize; 2]);

/// This rank's rows of the scaled normal equations: the local matrix over its halo, the
/// right-hand side of its halo's control points, the scaling D (by global control point)
/// and, across rotation seams, its share of the coupling C in the halo's numbering.
#[allow(clippy::type_complexity)]
fn assemble_share(
    j: &ShareJob,
    s: &SplineSpace,
    halo: &Halo,
) -> (
    LocalMatrix,
    Vec<[f64; 3]>,
    Option<Vec<f64>>,
    Option<crate::fit::rotated::Coupling>,
) {
    let (comm, local, setup, mine) = (j.comm, j.local, j.setup, j.mine);
    let topo = setup.topo(j.job);
    let mesh = &local.mesh;
    // This rank's share of the fit, with the whole mesh's size levels.
    let sizes = crate::fit::partial::element_sizes(mesh);
    let mut hmax = [sizes[..local.n_owned].iter().copied().fold(0.0, f64::max)];
    comm.max_f64(&mut hmax);
    // The ghosts' levels are left at 0: the scaling D of a control point is the largest
    // level of the own elements using it here, then over the ranks sharing it.
    let mut levels = crate::fit::partial::size_levels_below(&sizes, hmax[0]);
    levels[local.n_owned..].fill(0);
    drop(sizes);
    let fit_params = &setup.fit_params;
    let mut sys = crate::fit::partial::partial_normal_equations_levelled(
        s,
        mesh,
        topo,
        fit_params,
        setup.targets.as_ref(),
        mine,
        Some(&levels),
    );
    drop(levels);
    // D = 2^-k is exact, and D = 1 scales nothing: a rank without levels takes 1 everywhere.
    let mut d_halo: Vec<f64> = match &sys.scale {
        Some(d) => halo.global.iter().map(|&g| d[g as usize]).collect(),
        None => vec![1.0; halo.len()],
    };
    super::local::min_over_halo(comm, halo, &mut d_halo);
    let mut d = vec![1.0; s.n_control_points()];
    for (&g, &x) in halo.global.iter().zip(&d_halo) {
        d[g as usize] = x;
    }
    drop(d_halo);
    sys.matrix.scale_symmetric(&d);
    let coupling = sys.coupling.take().map(|mut c| {
        c.scale_symmetric(&d);
        c.restricted(&halo.global)
    });
    for (r, &d) in sys.rhs.iter_mut().zip(&d) {
        *r = r.map(|x| d * x);
    }
    sys.scale = Some(d);
    let b: Vec<[f64; 3]> = halo.global.iter().map(|&g| sys.rhs[g as usize]).collect();
    let scale = sys.scale.take();
    drop(sys.rhs);
    (
        LocalMatrix::from_matrix(sys.matrix, halo),
        b,
        scale,
        coupling,
    )
}

/// The post-fit Q2 marks of the sub-mesh's elements (own and ghost) from the control points
/// `fitted` of `s`, or `None` when no element of the mesh is marked (collective). Each rank
/// measures the boundary sides of its own elements; every rank gathers all of them (a 2D
/// boundary: a few hundred to a few thousand sides) and finds the same runs as the serial
/// [`crate::pipeline::misfit::misfit_elements`], the vertices keyed by node tag.
fn misfit_marks(
    comm: &dyn Comm,
    local: &LocalMesh,
    topo: &Topology,
    s: &crate::spline::SplineSpace,
    fitted: &[[f64; 3]],
    targets: &crate::fit::SmoothTargets,
) -> Option<Vec<bool>> {
    use crate::pipeline::misfit::{SideFigures, boundary_sides, marked_sides};
    let mesh = &local.mesh;
    let mut own = vec![false; mesh.n_elements()];
    own[..local.n_owned].fill(true);
    let sides = boundary_sides(mesh, topo, s, fitted, targets, &own);
    // Per side: its element's global id, 4 vertex keys (-1: none), deviation, over.
    const WIDTH: usize = 7;
    let mut send = Vec::with_capacity(WIDTH * sides.len());
    for side in &sides {
        let f = side.figures(topo, s, |v| local.global_vertex[v as usize]);
        send.push(local.global_element[side.element as usize] as f64);
        send.extend(
            f.vertices
                .iter()
                .map(|&k| if k == u64::MAX { -1.0 } else { k as f64 }),
        );
        send.push(f.deviation);
        send.push(f64::from(u8::from(f.over)));
    }
    let all: Vec<f64> = comm.all_gather_f64(&send).concat();
    let figures: Vec<SideFigures> = all
        .chunks_exact(WIDTH)
        .map(|c| SideFigures {
            vertices: std::array::from_fn(|i| {
                if c[1 + i] < 0.0 {
                    u64::MAX
                } else {
                    c[1 + i] as u64
                }
            }),
            deviation: c[5],
            over: c[6] != 0.0,
        })
        .collect();
    let marked: std::collections::HashSet<u64> = all
        .chunks_exact(WIDTH)
        .zip(marked_sides(&figures))
        .filter(|(_, m)| *m)
        .map(|(c, _)| c[0] as u64)
        .collect();
    if marked.is_empty() {
        return None;
    }
    Some(
        local
            .global_element
            .iter()
            .map(|g| marked.contains(g))
            .collect(),
    )
}

/// A rank's figures of one least-squares pass's fit ([`LeastSquares::fit`]).
struct RankFit {
    /// The halo of the pass's space.
    halo: Halo,
    cg: crate::solve::CgInfo,
    /// Stored entries of the rank's share of K and of the whole K.
    nonzeros: [usize; 2],
}

/// One least-squares pass of a rank's share.
type Pass = LeastSquares<RankFit>;

/// The spline passes of a rank's share ([`crate::pipeline::passes`], the serial job's
/// driver): the whole mesh's knot survey over the ranks ([`super::knots`]), each rank
/// fitting and blending its own elements, the blend's counts summed over the ranks, so every
/// rank decides alike and as the serial run. `bytes` adds the bytes sent in the fits and the
/// blends.
struct RankPasses<'a> {
    comm: &'a dyn Comm,
    local: &'a LocalMesh,
    topo: &'a Topology,
    mine: &'a [usize],
    seam_map: &'a std::collections::HashMap<u64, u64>,
    bytes: [u64; 2],
    /// From the uniform fit, as the serial second pass starts (from C0 with periodic pairs).
    warm_start: bool,
}

impl Reduction for RankPasses<'_> {
    fn reduce(&self, op: Reduce, v: &mut [f64]) {
        self.comm.reduce(op, v)
    }
    fn lowest_failed(&self, failed: bool) -> Option<usize> {
        self.comm.lowest_failed(failed)
    }
}

impl Passes for RankPasses<'_> {
    type Pass = Pass;
    type Survey = super::knots::SharedSurvey;
    fn elements(&self) -> usize {
        self.local.n_global as usize
    }
    // The rank's glued share is its `local`'s (the setup's seams are those).
    fn survey(&mut self, _: &SplineSetup, clock: &mut Clock) -> Self::Survey {
        let (comm, local, topo) = (self.comm, self.local, self.topo);
        clock.run(Stage::Spline, || super::knots::survey(comm, local, topo))
    }
    fn knots(
        &mut self,
        _: &SplineSetup,
        clock: &mut Clock,
        survey: Self::Survey,
        params: &KnotParams,
    ) -> Knots {
        let (comm, local, topo) = (self.comm, self.local, self.topo);
        clock.run(Stage::Spline, || {
            super::knots::knots(comm, survey, local, topo, params)
        })
    }
    fn run(
        &mut self,
        job: &Job,
        setup: &SplineSetup,
        clock: &mut Clock,
        previous: Option<&Pass>,
        most: Option<usize>,
        demote: Option<&Demoted>,
    ) -> Result<Pass, CurveError> {
        let previous = previous.map(|p| &p.space);
        least_squares_pass(self, job, setup, clock, previous, most, demote)
    }
    fn held(pass: &Pass) -> Result<usize, usize> {
        match &pass.blend {
            Ok((_, info)) => Ok(info.reduced_before_floor),
            Err(at_least) => Err(*at_least),
        }
    }
    fn finish(
        &mut self,
        job: &Job,
        setup: &SplineSetup,
        clock: &mut Clock,
        pass: Pass,
    ) -> Result<Pass, CurveError> {
        finish_blend(self, job, setup, clock, pass)
    }
    fn warm_start(&self) -> bool {
        self.warm_start
    }
    fn owned(&self, _: &Job) -> usize {
        self.local.n_owned
    }
    // By global element id: the marks of the own and ghost elements are the serial run's.
    fn unite(&self, marks: &mut [bool]) -> usize {
        let global = &self.local.global_element;
        let send: Vec<f64> = (0..marks.len())
            .filter(|&e| marks[e])
            .map(|e| global[e] as f64)
            .collect();
        let all: std::collections::HashSet<u64> = self
            .comm
            .all_gather_f64(&send)
            .concat()
            .into_iter()
            .map(|g| g as u64)
            .collect();
        for (m, g) in marks.iter_mut().zip(global) {
            *m = all.contains(g);
        }
        all.len()
    }
    fn space(pass: &Pass) -> &SplineSpace {
        &pass.space
    }
    fn factors(pass: &Pass) -> &[f32] {
        pass.blend.as_ref().map_or(&[][..], |b| &b.0.0[..])
    }
}

impl<'a> RankPasses<'a> {
    fn share_job<'j>(&self, job: &'j Job<'j>, setup: &'j SplineSetup) -> ShareJob<'j>
    where
        'a: 'j,
    {
        ShareJob {
            comm: self.comm,
            local: self.local,
            job,
            setup,
            mine: self.mine,
        }
    }
}

/// A rank's part of the least-squares pass ([`least_squares_pass`]): its rows of the fit
/// with the distributed CG over the halo of each space (timed as [`Stage::Partition`]), the
/// misfit sides of the whole boundary gathered, the blend judging its own elements in rounds
/// agreed over the ranks. `bytes` adds the bytes sent in the fits and their misfit rounds
/// (with the halos of the rebuilt spaces) and in the blends.
impl Share for RankPasses<'_> {
    type Fit = RankFit;
    fn fit(
        &mut self,
        job: &Job,
        setup: &SplineSetup,
        clock: &mut Clock,
        space: &SplineSpace,
        start: Option<&[[f64; 3]]>,
        round: usize,
    ) -> Result<(Vec<[f64; 3]>, RankFit), CurveError> {
        let (comm, local) = (self.comm, self.local);
        let before = comm.bytes_sent();
        // A space on the glued seams numbers its control points by the glued entities: so do
        // the halo's keys, for the serial run's aggregates.
        let reps = setup.live_seams().map(|_| self.seam_map);
        let halo = clock.run(Stage::Partition, || {
            super::local::halo(comm, local, job.topo, space, reps)
        });
        // The first space's halo is the pass's set-up; a misfit round's counts with its fit.
        let before = if round == 0 {
            comm.bytes_sent()
        } else {
            before
        };
        let j = self.share_job(job, setup);
        let (c_star, cg, nonzeros) = fit_stage(&j, clock, space, &halo, start)?;
        self.bytes[0] += comm.bytes_sent() - before;
        Ok((c_star, RankFit { halo, cg, nonzeros }))
    }
    fn misfit_marks(
        &mut self,
        job: &Job,
        setup: &SplineSetup,
        space: &SplineSpace,
        fitted: &[[f64; 3]],
        targets: &crate::fit::SmoothTargets,
    ) -> Option<Vec<bool>> {
        let before = self.comm.bytes_sent();
        let topo = setup.topo(job);
        let marks = misfit_marks(self.comm, self.local, topo, space, fitted, targets);
        self.bytes[0] += self.comm.bytes_sent() - before;
        marks
    }
    fn blend(
        &mut self,
        job: &Job,
        setup: &SplineSetup,
        space: &SplineSpace,
        most: Option<usize>,
    ) -> Result<Result<Blend, usize>, CurveError> {
        let (comm, local) = (self.comm, self.local);
        let before = comm.bytes_sent();
        let judged = LocalShare {
            comm,
            mine: self.mine,
            global: &local.global_element,
            local_of: local
                .global_element
                .iter()
                .enumerate()
                .map(|(i, &g)| (g, i))
                .collect(),
        };
        let blend = agreed(comm, blend_within(job, setup, space, most, &judged));
        self.bytes[1] += comm.bytes_sent() - before;
        blend
    }
}

/// This rank's read, setup, fit, certified blend, then the job's tail on its share (sampling,
/// quality and the report; see the module docs), each stage on `clock`; `start` is the job's.
fn run_share(
    comm: &dyn Comm,
    input: &Path,
    options: &CurveOptions,
    order: usize,
    mut clock: Clock,
    start: Instant,
) -> Result<Finished, CurveError> {
    let mut local = clock.run(Stage::Read, || {
        read_share(comm, input, GHOST_DEPTH, &options.mesh, None)
    })?;
    // Checks of a rank's own share fail on that rank alone: agreed before the next collective.
    let (mut topo, input_msj) = clock.run(Stage::Topology, || {
        let topo = agreed(comm, local_topology(input, &local))?;
        Ok::<_, CurveError>((topo, comm.input_min_scaled_jacobian(&local.mesh)))
    })?;
    // Periodic pairs over the whole mesh: every rank finds the same pairs, or the same error.
    let resolved = clock.run(Stage::Topology, || {
        periodic_pairs(comm, input, options, &local, &topo)
    })?;
    check_pyfr_names(input, options.periodic.pyfr_names, &resolved.pairs)?;
    // Periodic seams are glued in the spline space as serially: the share is read again
    // with its ghost rings run on across the seams (the elements across a seam are neighbours
    // there), then glued ([`super::periodic::glue_share`]; across rotations the fit couples
    // the coordinates), a single file's share and Gmsh's parts alike.
    let seam_map = resolved.seam_map();
    if !seam_map.is_empty() {
        local = clock.run(Stage::Read, || {
            read_share(comm, input, GHOST_DEPTH, &options.mesh, Some(&seam_map))
        })?;
        topo = clock.run(Stage::Topology, || {
            agreed(comm, local_topology(input, &local))
        })?;
    }
    let seams = clock.run(Stage::Spline, || {
        super::periodic::glue_share(comm, &local, &resolved)
    });
    let pairs = resolved.pairs;
    local.glued = seams.0.clone().map(std::sync::Arc::new);
    let mesh = &local.mesh;
    let executor = crate::exec::executor(&options.backend);
    let job = Job {
        input,
        options,
        mesh,
        topo: &topo,
        executor: executor.as_ref(),
    };
    // The smooth targets of the whole mesh on every rank's share.
    let inherit = clock.run(Stage::Spline, || {
        super::local::VertexHalo::new(comm, &local)
    });
    let mine: Vec<usize> = (0..local.n_owned).collect();
    let mut passes = RankPasses {
        comm,
        local: &local,
        topo: &topo,
        mine: &mine,
        seam_map: &seam_map,
        bytes: [0; 2],
        warm_start: options.periodic.pairs.is_empty(),
    };
    let (setup, pass) = spline_job(&mut passes, &job, &mut clock, seams, Some(&inherit))?;
    let [bytes_fit, bytes_validity] = passes.bytes;
    let LeastSquares {
        space,
        fit,
        blend,
        demoted,
    } = pass;
    let Ok((cache, blend)) = blend else {
        unreachable!("the pass kept ran its blend to the end")
    };
    let mut rank = RankJob {
        comm,
        local: &local,
        job: &job,
        setup: &setup,
        order,
        space: &space,
        fit: &fit,
        cache: Some(cache),
        blend,
        demoted,
        input_msj,
        pairs: &pairs,
        bytes: [bytes_fit, bytes_validity, 0],
        features: None,
        seam: ("c0", None),
        counts: [0; 4],
        sizes: [0; 2],
    };
    let (output, report) = finish_job(&mut rank, input, options, clock, start)?;
    let mut tag_names = local.mesh.tag_names.clone();
    if options.periodic.pyfr_names {
        for (i, p) in pairs.iter().enumerate() {
            tag_names.insert(p.master_tag, format!("periodic_{i}_l"));
            tag_names.insert(p.slave_tag, format!("periodic_{i}_r"));
        }
    }
    Ok(Finished {
        tag_names,
        output,
        report,
    })
}

impl JobShare for RankJob<'_> {
    type Output = RankOutput;
    fn sample(&mut self, clock: &mut Clock) -> Result<RankOutput, CurveError> {
        let (comm, local, job, setup) = (self.comm, self.local, self.job, self.setup);
        let (input, options, mesh) = (job.input, job.options, job.mesh);
        // The certified blend found, for sampling (its nets computed once).
        let (factors, nets) = self.cache.take().expect("the share is sampled once");
        let target_map = setup.target_map(job);
        let (ids_mesh, ids_topo) = setup.entity_mesh(job);
        let blended = Blended::with_cache(
            mesh,
            &target_map,
            self.space,
            ids_mesh,
            ids_topo,
            factors,
            nets,
        )
        .with_geometry(mesh);
        let bytes_before = comm.bytes_sent();
        let (output, features) = clock.run(Stage::Sample, || {
            let seams = super::periodic::Seams {
                pairs: self.pairs,
                input,
                depth: options.line_search.certificate_depth,
                boundary_rows: setup.boundary_rows(),
            };
            let mut output = sample_share(
                comm,
                local,
                job.topo,
                &blended,
                self.order,
                setup.features.as_ref(),
                Some(&seams),
            )?;
            super::sample::to_file_order(comm, local, &mut output);
            // The serial report's feature summary when any rank found features (absolute
            // deviations here; relative to the diagonal in the report). None, as serially,
            // when the whole mesh has no feature vertex: a rank's features may all lie on the
            // cut fringe of its ghost rings, which the summary does not count.
            let mut any = [f64::from(u8::from(setup.features.is_some()))];
            comm.max_f64(&mut any);
            let features = (any[0] > 0.0)
                .then(|| {
                    super::features::feature_report(
                        comm,
                        local,
                        setup.topo(job),
                        setup.features.as_ref(),
                        &options.features.params,
                        output.feature_deviation,
                        1.0,
                    )
                })
                .filter(|r| r.found.feature_vertices > 0);
            Ok::<_, CurveError>((output, features))
        })?;
        self.bytes[2] = comm.bytes_sent() - bytes_before;
        self.features = features;
        drop(blended);
        // Putting a glued space back on the sub-mesh may fail on one rank: c1 only when on all.
        let seam = setup.seam_continuity();
        let mut glued = [f64::from(u8::from(seam.0 == "c1"))];
        comm.min_f64(&mut glued);
        self.seam = match (glued[0] > 0.0, seam) {
            (false, ("c1", _)) => (
                "c0",
                Some(
                    "the glued spline space could not be put back on every rank's elements".into(),
                ),
            ),
            (_, seam) => seam,
        };
        Ok(output)
    }
    fn quality(
        &mut self,
        out: &RankOutput,
    ) -> Result<(f64, crate::deviation::BoundaryDeviation), CurveError> {
        let (comm, local) = (self.comm, self.local);
        let quality = super::sample::global_quality(comm, self.job.input, local, out)?;
        let class = |c: &ElementClass| -> [usize; 3] {
            [
                matches!(c, ElementClass::Spline) as usize,
                matches!(c, ElementClass::Q2(_)) as usize,
                (*c == ElementClass::Q2(Q2Reason::BoundaryKink)) as usize,
            ]
        };
        let halo = &self.fit.halo;
        let mut counts = [halo.owned.iter().filter(|&&o| o).count() as u64, 0, 0, 0];
        for c in &self.space.classes[..local.n_owned] {
            for (n, x) in counts[1..].iter_mut().zip(class(c)) {
                *n += x as u64;
            }
        }
        let npf = (self.order + 1).pow(out.dim as u32 - 1);
        let mut sizes = [
            out.node_tags.len() as u64,
            (out.boundary.len() / npf) as u64,
        ];
        comm.sum_u64(&mut counts);
        comm.sum_u64(&mut sizes);
        self.counts = counts.map(|c| c as usize);
        self.sizes = sizes;
        Ok(quality)
    }
    fn outcomes(
        &mut self,
        out: &RankOutput,
        (min_sj, deviation): (f64, crate::deviation::BoundaryDeviation),
        clock: &Clock,
    ) -> Outcomes {
        let (comm, local, setup) = (self.comm, self.local, self.setup);
        let RankFit { halo, cg, nonzeros } = self.fit;
        let [bytes_fit, bytes_validity, bytes_sample] = self.bytes;
        let figures = RankFigures {
            rank: comm.rank(),
            elements: local.n_owned,
            ghost_elements: local.mesh.n_elements() - local.n_owned,
            control_points: halo.len(),
            owned_control_points: halo.owned.iter().filter(|&&o| o).count(),
            shared_control_points: halo.shared(),
            neighbours: halo.neighbours.len(),
            matrix_nonzeros: nonzeros[0],
            bytes_sent: comm.bytes_sent(),
            bytes_fit,
            bytes_validity,
            bytes_gather: bytes_sample,
            peak_memory_bytes: peak_memory_bytes(),
            peak_memory_by_stage: clock.peaks(),
            timings: clock.timings().clone(),
        };
        let per_rank = gather_figures(comm, &figures);
        let counts = self.counts;
        let knot_intervals = setup.knot_intervals;
        let space = SpaceCounts {
            control_points: counts[0],
            spline_elements: counts[1],
            q2_elements: counts[2],
            kink_elements: counts[3],
            knot_intervals,
            knot_passes: setup.knot_passes,
            extraordinary_midpoint: setup.fit_params.weights.extraordinary_midpoint,
            features: self.features.take().map(|mut f| {
                f.feature_vertex_deviation_max /= deviation.diagonal;
                f.planarity_max /= deviation.diagonal;
                f
            }),
        };
        let n_global = local.n_global as usize;
        // Coupled across rotation seams where some rank's elements see a point rotated (the
        // ranks' coupled CG runs on the CPU).
        let mut coupled = [f64::from(u8::from(self.space.extraction.has_frames()))];
        comm.max_f64(&mut coupled);
        Outcomes {
            dimension: out.dim,
            elements: n_global,
            order: self.order,
            output_nodes: self.sizes[0] as usize,
            output_elements: n_global,
            boundary_facets: self.sizes[1] as usize,
            spline: Some(SplineFigures {
                knot_surfaces: (knot_intervals == KnotIntervals::Graded).then_some(setup.knot_info),
                demoted: self.demoted,
                // As serially on the CPU (`pcg_coupled` above).
                coupled: (coupled[0] > 0.0).then_some(crate::fit::CoupledRun::cpu(
                    crate::fit::rotated::OnK::BlockJacobiPair,
                )),
                ..SplineFigures::blended(
                    space,
                    (crate::fit::FitSolver::Cg, *cg, nonzeros[1]),
                    self.blend.clone(),
                )
            }),
            snapped: None,
            elastic: None,
            periodic: periodic_report(
                self.pairs,
                out,
                &self.seam,
                self.job.options,
                deviation.diagonal,
            ),
            input_min_scaled_jacobian: self.input_msj,
            min_scaled_jacobian: min_sj,
            deviation,
            // The distributed job runs on the CPU only.
            gpu: None,
            per_rank: Some(per_rank),
        }
    }
}

/// The periodic pairs of `--periodic` and of the input's `$Periodic` over the whole mesh
/// ([`super::periodic::resolve`]): the same pairs, or the same error, on every rank.
/// Collective when there are pairs.
fn periodic_pairs(
    comm: &dyn Comm,
    input: &Path,
    options: &CurveOptions,
    local: &LocalMesh,
    topo: &Topology,
) -> Result<super::periodic::Resolved, CurveError> {
    // Every rank read the file's `$Periodic` links (the same on every rank).
    if options.periodic.pairs.is_empty() && local.mesh.declared_periodic.is_empty() {
        return Ok(Default::default());
    }
    let periodic_err = |source| CurveError::Periodic {
        input: input.to_owned(),
        source,
    };
    super::periodic::resolve(comm, local, topo, &options.periodic.pairs).map_err(periodic_err)
}

/// Run the distributed `curve` job on every rank of `comm` (see the module docs): every rank
/// returns its share of the output and the report (the same on every rank; `output` empty
/// and `timings` without `write`, set when written).
pub fn curve(
    comm: &dyn Comm,
    input: &Path,
    options: &CurveOptions,
) -> Result<Finished, CurveError> {
    check_supported(options)?;
    // The serial job's option checks (elastic is refused above, so no elastic parameters).
    let (order, _) = crate::pipeline::check_options(options)?;
    let start = Instant::now();
    run_share(
        comm,
        input,
        options,
        order,
        Clock::with_peaks(&Silent),
        start,
    )
}

/// The report's `periodic` (and the seams' certified bound) when the job has pairs: the
/// serial report's fields.
fn periodic_report(
    pairs: &[crate::mesh::periodic::PeriodicPair],
    output: &RankOutput,
    seam: &(&'static str, Option<String>),
    options: &CurveOptions,
    diagonal: f64,
) -> Option<(f64, crate::pipeline::PeriodicReport)> {
    let info = output.images?;
    let report = crate::pipeline::PeriodicReport {
        pairs: pairs.iter().map(|p| p.summary(diagonal)).collect(),
        node_pairs: output.periodic.iter().map(|l| l.node_pairs.len()).sum(),
        max_seam_shift: info.max_shift / diagonal,
        written_mismatch: info.max_mismatch / diagonal,
        recertified_elements: info.recertified,
        seam: seam.0,
        seam_c0_reason: seam.1.clone(),
        pyfr_names: options.periodic.pyfr_names,
    };
    Some((info.min_det_bound, report))
}

/// Stages whose seconds and peak memory are reported per rank.
const RANK_STAGES: [Stage; 10] = [
    Stage::Read,
    Stage::Topology,
    Stage::Spline,
    Stage::Partition,
    Stage::Fit,
    Stage::FitAssembly,
    Stage::FitCg,
    Stage::Validity,
    Stage::Sample,
    Stage::Quality,
];

/// Every rank's figures on every rank (a few numbers each).
fn gather_figures(comm: &dyn Comm, f: &RankFigures) -> Vec<RankFigures> {
    let mut v = vec![
        f.elements as f64,
        f.control_points as f64,
        f.owned_control_points as f64,
        f.shared_control_points as f64,
        f.neighbours as f64,
        f.matrix_nonzeros as f64,
        f.bytes_sent as f64,
        f.peak_memory_bytes as f64,
        f.bytes_fit as f64,
        f.bytes_validity as f64,
        f.bytes_gather as f64,
        f.ghost_elements as f64,
    ];
    v.extend(
        RANK_STAGES
            .iter()
            .map(|s| f.timings.get(s.key()).copied().unwrap_or(0.0)),
    );
    v.extend(
        RANK_STAGES
            .iter()
            .map(|s| f.peak_memory_by_stage.get(s.key()).copied().unwrap_or(0) as f64),
    );
    comm.all_gather_f64(&v)
        .into_iter()
        .enumerate()
        .map(|(rank, v)| RankFigures {
            rank,
            elements: v[0] as usize,
            control_points: v[1] as usize,
            owned_control_points: v[2] as usize,
            shared_control_points: v[3] as usize,
            neighbours: v[4] as usize,
            matrix_nonzeros: v[5] as usize,
            bytes_sent: v[6] as u64,
            peak_memory_bytes: v[7] as u64,
            bytes_fit: v[8] as u64,
            bytes_validity: v[9] as u64,
            bytes_gather: v[10] as u64,
            ghost_elements: v[11] as usize,
            timings: RANK_STAGES
                .iter()
                .zip(&v[12..])
                .map(|(s, &t)| (s.key().to_string(), t))
                .collect(),
            peak_memory_by_stage: RANK_STAGES
                .iter()
                .zip(&v[12 + RANK_STAGES.len()..])
                .map(|(s, &m)| (s.key().to_string(), m as u64))
                .collect(),
        })
        .collect()
}
