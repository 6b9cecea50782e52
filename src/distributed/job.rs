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
//! ([`super::share`], [`super::read`]); build the topology, features, smooth targets
//! and spline space on that sub-mesh with the serial stage functions
//! (`pipeline::spline::SplineSetup`); with graded or `auto` knots, survey the whole mesh's
//! knot surfaces and take the serial knot weights ([`super::knots`]), `auto` deciding on the
//! whole mesh's figures as the serial `curve_spline` does (`spline_passes`, one or two
//! passes of what follows); agree on the shared control points by keys of
//! global entity ids ([`super::local`]); assemble the normal equations over its own elements
//! with the whole mesh's size levels ([`crate::fit::partial`]); solve them with the
//! distributed CG ([`super::cg`]) under the serial preconditioner; run the certified blend on
//! its own elements, the ranks agreeing on the rejected elements of every round in global ids
//! ([`crate::validity::blend::blend_search_shared`]); sample its own elements with a global
//! node numbering ([`super::sample`]), with `--periodic` the pairs resolved over the whole mesh
//! and the image sides' nodes made the transform of their masters' ([`super::periodic`]),
//! check them and route them back to their file runs for the collective write; no rank reads
//! or holds the whole mesh.
//! Invariant: the result is the serial run's (the same knots too) up to the order of the
//! sums: the CG applies the serial preconditioner on the serial aggregates
//! ([`super::blocks`]), so it takes the serial iterates and stops where the serial solve
//! stops; the blend's factors are the serial search's for the same fitted map.

use super::blocks::Aggregation;
use super::cg::{Halo, LocalMatrix, pcg};
use super::comm::Comm;
use super::local::{GHOST_DEPTH, LocalShare};
use super::read::LocalMesh;
use super::sample::{RankOutput, sample_share};
use super::share::read_share;
use crate::mesh::Topology;
use crate::pipeline::clock::{Clock, peak_memory_bytes};
use crate::pipeline::spline::{self, SplineSetup};
use crate::pipeline::{
    CurveError, CurveOptions, CurveReport, Geometry, Job, LineSearchMode, Method, Outcomes,
    RankFigures, SpaceCounts, SplineFigures,
};
use crate::progress::{Silent, Stage};
use crate::spline::{ElementClass, KnotIntervals, Q2Reason, SplineSpace};
use crate::validity::CpuCertifier;
use crate::validity::blend::{Blended, blend_search_shared};
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

/// The options the distributed job runs; anything else is one bounded error line.
fn check_supported(options: &CurveOptions) -> Result<(), CurveError> {
    let unsupported = |what: &str| {
        Err(CurveError::Options(format!(
            "{what} is not available under mpirun yet (docs/distributed.md); run it on one process"
        )))
    };
    if options.geometry != Geometry::SplineFitted {
        return unsupported("--straight or --fit none");
    }
    if options.energy.is_some() {
        return unsupported("--fit energy");
    }
    if !matches!(options.method, Method::Iga) {
        return unsupported("--method elastic");
    }
    if options.backend.gpu().is_some() {
        return unsupported("the GPU backend");
    }
    if options.subdivide.is_some() {
        return unsupported("--subdivide");
    }
    if options.snap_boundary {
        return unsupported("--snap-boundary");
    }
    // The edits name vertices by their place in the file; a rank's sub-mesh numbers them
    // otherwise, so they would hit other vertices.
    if options.features.edits.is_some() {
        return unsupported("--feature-edits");
    }
    // The deep midpoints are found on the mesh a rank holds, whose cut fringe is not the
    // whole mesh's boundary.
    if options.fit.weights.deep_midpoint.is_some() {
        return unsupported("--w-deep-midpoint");
    }
    // The sweeps of block Gauss–Seidel run across the whole matrix in one order (the CG
    // refuses it too: `CgError::Unavailable`).
    if let crate::solve::CgPreconditioner::BlockSgs { .. } = options.fit.cg.preconditioner {
        return unsupported("--cg-preconditioner block-sgs");
    }
    Ok(())
}

/// [`super::comm::agree`] for a stage of the job: the ranks that did not fail stop with an
/// error the launcher does not print (the lowest failing rank prints its own).
fn agree<T>(comm: &dyn Comm, r: Result<T, CurveError>) -> Result<T, CurveError> {
    super::comm::agree(comm, r, |q| {
        CurveError::Options(format!("stopped: rank {q} failed"))
    })
}

/// What a rank has after its share of the setup, fit and blend.
struct Share {
    local: LocalMesh,
    cg: crate::solve::CgInfo,
    blend: crate::validity::blend::BlendInfo,
    /// This rank's share of the sampled output, in global node tags.
    output: RankOutput,
    /// Own control points (counted once over the ranks), spline, Q2 and kink elements.
    counts: [usize; 4],
    knot_intervals: KnotIntervals,
    /// Spline passes run to choose the knots (`auto`: 1 or 2).
    knot_passes: usize,
    /// The whole mesh's knot surfaces, with graded knots.
    knot_surfaces: Option<crate::spline::KnotSurfaceInfo>,
    input_msj: f64,
    halo: Halo,
    nonzeros: usize,
    bytes_fit: u64,
    bytes_validity: u64,
    bytes_sample: u64,
    /// Blend entities this rank owns whose factor was reduced (below the fitted map, at or
    /// below the target map, at the straight elevation): [`damped_owned`].
    damped_owned: [usize; 3],
    /// The whole mesh's feature summary (deviations absolute), when any rank found features.
    features: Option<crate::mesh::features::FeatureReport>,
    /// The periodic pairs (`--periodic`), resolved over the whole mesh.
    pairs: Vec<crate::mesh::periodic::PeriodicPair>,
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
    s: &mut SplineSpace,
    halo: &Halo,
    start: Option<&[[f64; 3]]>,
) -> Result<(crate::solve::CgInfo, usize), CurveError> {
    let t = Instant::now();
    let fit = fit_share(j, clock, s, halo, start);
    clock.add(Stage::Fit, t.elapsed().as_secs_f64());
    fit
}

/// This rank's share of the fit: its rows of the normal equations with the whole mesh's size
/// levels, the scaling agreed over the halo ([`Stage::FitAssembly`]), the distributed CG
/// with its preconditioner's aggregates grown first ([`Stage::FitCg`]), and the fitted
/// control points (projected onto planar patches) in `s`. The CG starts from the control
/// points `start` where given (one per control point of `s`), as the serial fit's warm start
/// does ([`crate::fit::fit_with_targets_from`]). Returns the CG's figures and the local
/// matrix's stored entries.
fn fit_share(
    j: &ShareJob,
    clock: &mut Clock,
    s: &mut SplineSpace,
    halo: &Halo,
    start: Option<&[[f64; 3]]>,
) -> Result<(crate::solve::CgInfo, usize), CurveError> {
    let (comm, topo, setup) = (j.comm, j.job.topo, j.setup);
    let fit_params = &setup.fit_params;
    // The preconditioner's aggregates (the serial run's: rank 0 grows them on the whole
    // mesh's stencils) before the assembly, while a rank holds least.
    let aggregation = clock.run(Stage::FitCg, || {
        let stencils = super::blocks::own_stencils(s, halo, j.mine);
        Aggregation::for_preconditioner(comm, halo, &stencils, &fit_params.cg.preconditioner)
    });
    let (k, b, scale) = clock.run(Stage::FitAssembly, || assemble_share(j, s, halo));
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
    let cg = clock
        .run(Stage::FitCg, || {
            pcg(
                comm,
                halo,
                &k,
                &b,
                &mut delta,
                &fit_params.cg,
                aggregation.as_ref(),
            )
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
    s.control_points = c_star;
    Ok((cg, k.nonzeros()))
}

/// This rank's rows of the scaled normal equations: the local matrix over its halo, the
/// right-hand side of its halo's control points and the scaling D (by global control point).
#[allow(clippy::type_complexity)]
fn assemble_share(
    j: &ShareJob,
    s: &SplineSpace,
    halo: &Halo,
) -> (LocalMatrix, Vec<[f64; 3]>, Option<Vec<f64>>) {
    let (comm, local, topo, setup, mine) = (j.comm, j.local, j.job.topo, j.setup, j.mine);
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
    for (r, &d) in sys.rhs.iter_mut().zip(&d) {
        *r = r.map(|x| d * x);
    }
    sys.scale = Some(d);
    let b: Vec<[f64; 3]> = halo.global.iter().map(|&g| sys.rhs[g as usize]).collect();
    let scale = sys.scale.take();
    drop(sys.rhs);
    (LocalMatrix::from_matrix(sys.matrix, halo), b, scale)
}

/// The post-fit Q2 marks of the sub-mesh's elements (own and ghost) from the fitted control
/// points of `s`, or `None` when no element of the mesh is marked (collective). Each rank
/// measures the boundary sides of its own elements; every rank gathers all of them (a 2D
/// boundary: a few hundred to a few thousand sides) and finds the same runs as the serial
/// [`crate::pipeline::misfit::misfit_elements`], the vertices keyed by node tag.
fn misfit_marks(
    comm: &dyn Comm,
    local: &LocalMesh,
    topo: &Topology,
    s: &crate::spline::SplineSpace,
    targets: &crate::fit::SmoothTargets,
) -> Option<Vec<bool>> {
    use crate::pipeline::misfit::{SideFigures, boundary_sides, marked_sides};
    let mesh = &local.mesh;
    let mut own = vec![false; mesh.n_elements()];
    own[..local.n_owned].fill(true);
    let sides = boundary_sides(mesh, topo, s, &s.control_points, targets, &own);
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

/// What the spline passes of a rank's share read: the job (on the sub-mesh, with the options
/// asked for), the communicator and the sub-mesh's own elements.
struct Passes<'a> {
    comm: &'a dyn Comm,
    local: &'a LocalMesh,
    job: &'a Job<'a>,
    mine: &'a [usize],
}

/// One spline pass of a rank's share: its space, halo and fit, and the certified blend's
/// outcome (factors and nets owned, so that the setup can change knots between passes).
struct Pass {
    s: SplineSpace,
    halo: Halo,
    cg: crate::solve::CgInfo,
    nonzeros: usize,
    factors: Vec<f32>,
    nets: crate::validity::blend::NetCache,
    blend: crate::validity::blend::BlendInfo,
}

impl Pass {
    /// Elements the blend holds back over the whole mesh (what `auto` decides on).
    fn held(&self) -> usize {
        self.blend.reduced_elements
    }
}

/// The spline passes of the job's knot intervals on this rank's share, with the serial
/// `curve_spline`'s rules (`pipeline::spline`): uniform or graded knots as asked; `auto`
/// graded straight away where the whole mesh's graded share reaches
/// [`crate::spline::AUTO_GRADED_SHARE`], else uniform, then graded (from the uniform fit)
/// where the uniform blend holds back too many elements over the whole mesh, kept when
/// decisive. Every rank decides alike: on the whole mesh's survey ([`super::knots`]) and the
/// blends' global counts. `setup` ends with the knots of the pass returned; `bytes` adds the
/// bytes sent in the fits and the blends.
fn spline_passes(
    p: &Passes,
    setup: &mut SplineSetup,
    clock: &mut Clock,
    bytes: &mut [u64; 2],
) -> Result<Pass, CurveError> {
    let (comm, local, job) = (p.comm, p.local, p.job);
    let options = job.options;
    let weights = options.fit.weights;
    let (uniform, graded) = (
        options.with_knots(KnotIntervals::Uniform),
        options.with_knots(KnotIntervals::Graded),
    );
    let uniform_job = Job {
        options: &uniform,
        ..*job
    };
    let graded_job = Job {
        options: &graded,
        ..*job
    };
    let survey = |clock: &mut Clock| {
        clock.run(Stage::Spline, || {
            super::knots::survey(comm, local, job.topo)
        })
    };
    let graded_knots = |clock: &mut Clock, survey| {
        clock.run(Stage::Spline, || {
            super::knots::knots(comm, survey, local, job.topo, &graded.knots)
        })
    };
    let pass =
        |setup: &SplineSetup, job: &Job, clock: &mut Clock, bytes: &mut [u64; 2], previous| {
            let j = ShareJob {
                comm,
                local,
                job,
                setup,
                mine: p.mine,
            };
            share_pass(&j, clock, previous, bytes)
        };
    match options.knots.intervals {
        KnotIntervals::Uniform => pass(setup, &uniform_job, clock, bytes, None),
        KnotIntervals::Graded => {
            let shared = survey(clock);
            let knots = graded_knots(clock, shared);
            setup.set_knots(KnotIntervals::Graded, knots, weights);
            pass(setup, &graded_job, clock, bytes, None)
        }
        KnotIntervals::Auto => {
            let shared = survey(clock);
            if shared.graded_share >= crate::spline::AUTO_GRADED_SHARE {
                let knots = graded_knots(clock, shared);
                setup.set_knots(KnotIntervals::Graded, knots, weights);
                return pass(setup, &graded_job, clock, bytes, None);
            }
            let near_uniform = shared.max_abs_log_ratio < crate::spline::AUTO_MIN_LOG_RATIO;
            // Not held through the uniform pass (rank 0 holds the whole mesh's survey).
            drop(shared);
            let first = pass(setup, &uniform_job, clock, bytes, None)?;
            let n_global = local.n_global as usize;
            if !spline::auto_holds_back_too_many(first.held(), n_global) || near_uniform {
                return Ok(first);
            }
            let shared = survey(clock);
            let knots = graded_knots(clock, shared);
            let uniform_knots = setup.set_knots(KnotIntervals::Graded, knots, weights);
            setup.knot_passes = 2;
            // From the uniform fit, as the serial second pass starts (from C0 with periodic
            // pairs, whose passes have a setup each there).
            let previous = options.periodic.pairs.is_empty().then_some(&first.s);
            let second = pass(setup, &graded_job, clock, bytes, previous)?;
            if spline::auto_graded_is_decisive(second.held(), first.held()) {
                return Ok(second);
            }
            setup.set_knots(KnotIntervals::Uniform, uniform_knots, weights);
            Ok(first)
        }
    }
}

/// One spline pass of this rank's share (see [`Pass`]): the space of `j.setup`, its halo, the
/// fit (from `previous`'s fitted control points where given; in 2D with the serial run's
/// post-fit Q2 rounds), then the certified blend, each rank judging its own elements.
fn share_pass(
    j: &ShareJob,
    clock: &mut Clock,
    previous: Option<&SplineSpace>,
    bytes: &mut [u64; 2],
) -> Result<Pass, CurveError> {
    let (comm, local, job, setup) = (j.comm, j.local, j.job, j.setup);
    let (mesh, topo, options) = (&local.mesh, job.topo, job.options);
    let mut s = clock.run(Stage::Spline, || setup.build(job, &[]));
    let mut halo = clock.run(Stage::Partition, || {
        super::local::halo(comm, local, topo, &s)
    });
    let before_fit = comm.bytes_sent();
    let start = previous.map(|p| spline::carry_over(p, &p.control_points, &s));
    let (mut cg, mut nonzeros) = fit_stage(j, clock, &mut s, &halo, start.as_deref())?;
    drop(start);
    // The serial run's post-fit Q2 choice of 2D meshes (`pipeline::misfit`), its runs of
    // misfit sides found over the whole boundary: mark, rebuild, refit.
    if let Some(targets) = setup.targets.as_ref().filter(|_| topo.dim == 2) {
        let mut misfit = vec![false; mesh.n_elements()];
        for _ in 0..crate::pipeline::misfit::MISFIT_ROUNDS {
            let marks = clock.run(Stage::Spline, || {
                misfit_marks(comm, local, topo, &s, targets)
            });
            let Some(marks) = marks else {
                break;
            };
            for (m, x) in misfit.iter_mut().zip(marks) {
                *m |= x;
            }
            s = clock.run(Stage::Spline, || {
                setup.build_with_misfits(job, &[], &misfit)
            });
            halo = clock.run(Stage::Partition, || {
                super::local::halo(comm, local, topo, &s)
            });
            (cg, nonzeros) = fit_stage(j, clock, &mut s, &halo, None)?;
        }
    }
    let before_blend = comm.bytes_sent();
    bytes[0] += before_blend - before_fit;

    // The certified blend, each rank judging its own elements.
    let target_map = clock.run(Stage::Validity, || setup.target_map(job));
    let (factors, nets, blend) = clock.run(Stage::Validity, || {
        let blend_params = options
            .line_search
            .blend(options.line_search_mode == LineSearchMode::Global);
        let mut blended = Blended::new(mesh, &target_map, &s, mesh, topo, Vec::new());
        let share = LocalShare {
            comm,
            mine: j.mine,
            global: &local.global_element,
            local_of: local
                .global_element
                .iter()
                .enumerate()
                .map(|(i, &g)| (g, i))
                .collect(),
            n_local: mesh.n_elements(),
            n_global: local.n_global as usize,
        };
        let blend = blend_search_shared(&CpuCertifier, &mut blended, &blend_params, &share)
            .map_err(|source| CurveError::Blend {
                input: job.input.to_owned(),
                source,
            });
        let blend = agree(comm, blend)?;
        let factors = std::mem::take(&mut blended.factors);
        Ok::<_, CurveError>((factors, blended.into_cache(), blend))
    })?;
    bytes[1] += comm.bytes_sent() - before_blend;
    Ok(Pass {
        s,
        halo,
        cg,
        nonzeros,
        factors,
        nets,
        blend,
    })
}

/// This rank's read, setup, fit, certified blend and sampling (see the module docs), each
/// stage on `clock`.
fn run_share(
    comm: &dyn Comm,
    input: &Path,
    options: &CurveOptions,
    order: usize,
    clock: &mut Clock,
) -> Result<Share, CurveError> {
    let local = clock.run(Stage::Read, || {
        read_share(comm, input, GHOST_DEPTH, &options.mesh)
    })?;
    let mesh = &local.mesh;
    // Checks of a rank's own share fail on that rank alone: agreed before the next collective.
    let (topo, input_msj) = clock.run(Stage::Topology, || {
        let topo = agree(comm, local_topology(input, &local))?;
        let mut msj = [mesh.min_scaled_jacobian().map_or(f64::INFINITY, |m| m.0)];
        comm.min_f64(&mut msj);
        Ok::<_, CurveError>((topo, msj[0]))
    })?;
    // Periodic pairs over the whole mesh: every rank finds the same pairs, or the same error.
    let pairs = clock.run(Stage::Topology, || {
        periodic_pairs(comm, input, options, &local, &topo)
    })?;
    let executor = crate::exec::executor(&options.backend);
    let job = Job {
        input,
        options,
        mesh,
        topo: &topo,
        executor: executor.as_ref(),
    };
    // The setup of uniform knots; graded ones are put in place once surveyed (as the serial
    // `curve_spline` does: the features, kinks and targets do not depend on the knots).
    let uniform = options.with_knots(KnotIntervals::Uniform);
    let uniform_job = Job {
        options: &uniform,
        ..job
    };
    let mut setup = clock.run(Stage::Spline, || {
        agree(comm, SplineSetup::new(&uniform_job, &[]))
    })?;
    let mine: Vec<usize> = (0..local.n_owned).collect();
    let mut bytes = [0u64; 2];
    let pass = spline_passes(
        &Passes {
            comm,
            local: &local,
            job: &job,
            mine: &mine,
        },
        &mut setup,
        clock,
        &mut bytes,
    )?;
    let [bytes_fit, bytes_validity] = bytes;
    let Pass {
        s,
        halo,
        cg,
        nonzeros,
        factors,
        nets,
        blend,
    } = pass;
    // The certified blend found, for sampling (its nets computed once).
    let target_map = setup.target_map(&job);
    let blended = Blended::with_cache(mesh, &target_map, &s, mesh, &topo, factors, nets);
    let damped_owned = damped_owned(&local, &blended);
    let bytes_before = comm.bytes_sent();
    let (output, features) = clock.run(Stage::Sample, || {
        let seams = super::periodic::Seams {
            pairs: &pairs,
            input,
            depth: options.line_search.certificate_depth,
        };
        let mut output = sample_share(
            comm,
            &local,
            &topo,
            &blended,
            order,
            setup.features.as_ref(),
            Some(&seams),
        )?;
        super::sample::to_file_order(comm, &local, &mut output);
        // The serial report's feature summary when any rank found features (absolute
        // deviations here; relative to the diagonal in the report).
        let mut any = [f64::from(u8::from(setup.features.is_some()))];
        comm.max_f64(&mut any);
        let features = (any[0] > 0.0).then(|| {
            super::features::feature_report(
                comm,
                &local,
                &topo,
                setup.features.as_ref(),
                &options.features.params,
                output.feature_deviation,
                1.0,
            )
        });
        Ok::<_, CurveError>((output, features))
    })?;
    let bytes_sample = comm.bytes_sent() - bytes_before;
    let class = |c: &ElementClass| -> [usize; 3] {
        [
            matches!(c, ElementClass::Spline) as usize,
            matches!(c, ElementClass::Q2(_)) as usize,
            (*c == ElementClass::Q2(Q2Reason::BoundaryKink)) as usize,
        ]
    };
    let mut counts = [halo.owned.iter().filter(|&&o| o).count(), 0, 0, 0];
    for c in &s.classes[..local.n_owned] {
        for (n, x) in counts[1..].iter_mut().zip(class(c)) {
            *n += x;
        }
    }
    let knot_intervals = setup.knot_intervals;
    drop(blended);
    Ok(Share {
        local,
        cg,
        blend,
        output,
        counts,
        knot_intervals,
        knot_passes: setup.knot_passes,
        knot_surfaces: (knot_intervals == KnotIntervals::Graded).then_some(setup.knot_info),
        input_msj,
        halo,
        nonzeros,
        bytes_fit,
        bytes_validity,
        bytes_sample,
        damped_owned,
        features,
        pairs,
    })
}

/// The periodic pairs of `--periodic` over the whole mesh ([`super::periodic::resolve`]):
/// the same pairs, or the same error, on every rank. Collective when pairs are given.
fn periodic_pairs(
    comm: &dyn Comm,
    input: &Path,
    options: &CurveOptions,
    local: &LocalMesh,
    topo: &Topology,
) -> Result<Vec<crate::mesh::periodic::PeriodicPair>, CurveError> {
    let periodic_err = |source| CurveError::Periodic {
        input: input.to_owned(),
        source,
    };
    if options.periodic.pairs.is_empty() {
        // Curved without its pairs, the sides would no longer be images of each other and the
        // output would carry no pair, which the file says it has: refused, as the serial job
        // refuses a link it cannot use.
        if local.declares_periodic {
            return Err(periodic_err(crate::mesh::periodic::PeriodicError {
                spec: "$Periodic".into(),
                what: "the input's periodic section is not read under mpirun yet: give its pairs with --periodic A:B (docs/periodic.md)".into(),
            }));
        }
        if options.periodic.pyfr_names {
            // The serial job's refusal (`pipeline::curve`); under mpirun no `$Periodic` is read.
            return Err(periodic_err(crate::mesh::periodic::PeriodicError {
                spec: "--periodic-pyfr-names".into(),
                what: "the mesh has no periodic pair to name: give one with --periodic A:B (under mpirun an input's $Periodic section is not read)".into(),
            }));
        }
        return Ok(Vec::new());
    }
    super::periodic::resolve(comm, local, topo, &options.periodic.pairs).map_err(periodic_err)
}

/// Blend entities (vertices, edges, faces, cells) this rank owns whose factor was reduced
/// (below 2, at most 1, 0: the serial `BlendInfo`'s reduced, target and straight points): an
/// entity is owned by the rank of the lowest global element containing it (every element
/// containing an entity of an own element is in the sub-mesh), so the sum over the ranks
/// counts each entity once, as the serial report does.
fn damped_owned(local: &LocalMesh, blended: &Blended) -> [usize; 3] {
    if blended.factors.is_empty() {
        return [0; 3];
    }
    let d = local.mesh.dim;
    let np = if d == 2 { 9 } else { 27 };
    // Each entity is counted by the rank holding the lowest global element around it (its
    // local index is kept: own elements come first, whatever the partition).
    let mut lowest = vec![(u64::MAX, usize::MAX); blended.factors.len()];
    for e in 0..local.mesh.n_elements() {
        let g = local.global_element[e];
        for &id in &blended.ids.of(e)[..np] {
            let l = &mut lowest[id as usize];
            if g < l.0 {
                *l = (g, e);
            }
        }
    }
    let owned: Vec<f32> = lowest
        .iter()
        .zip(&blended.factors)
        .filter(|&(&(_, e), _)| e < local.n_owned)
        .map(|(_, &f)| f)
        .collect();
    [
        owned
            .iter()
            .filter(|&&f| f < crate::validity::blend::FITTED)
            .count(),
        owned.iter().filter(|&&f| f <= 1.0).count(),
        owned.iter().filter(|&&f| f == 0.0).count(),
    ]
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
    let mut clock = Clock::with_peaks(&Silent);
    let share = run_share(comm, input, options, order, &mut clock)?;
    let out = &share.output;
    let (min_sj, deviation, counts, sizes) = clock.run(Stage::Quality, || {
        let (min_sj, deviation) = super::sample::global_quality(comm, input, &share.local, out)?;
        let mut counts = share.counts.map(|c| c as u64);
        let npf = (order + 1).pow(out.dim as u32 - 1);
        let mut sizes = [
            out.node_tags.len() as u64,
            (out.boundary.len() / npf) as u64,
            share.damped_owned[0] as u64,
            share.damped_owned[1] as u64,
            share.damped_owned[2] as u64,
        ];
        comm.sum_u64(&mut counts);
        comm.sum_u64(&mut sizes);
        Ok::<_, CurveError>((min_sj, deviation, counts.map(|c| c as usize), sizes))
    })?;
    let figures = RankFigures {
        rank: comm.rank(),
        elements: share.local.n_owned,
        ghost_elements: share.local.mesh.n_elements() - share.local.n_owned,
        control_points: share.halo.len(),
        owned_control_points: share.halo.owned.iter().filter(|&&o| o).count(),
        shared_control_points: share.halo.shared(),
        neighbours: share.halo.neighbours.len(),
        matrix_nonzeros: share.nonzeros,
        bytes_sent: comm.bytes_sent(),
        bytes_fit: share.bytes_fit,
        bytes_validity: share.bytes_validity,
        bytes_gather: share.bytes_sample,
        peak_memory_bytes: peak_memory_bytes(),
        peak_memory_by_stage: clock.peaks(),
        timings: clock.timings().clone(),
    };
    let per_rank = gather_figures(comm, &figures);
    clock.set(Stage::Total, start.elapsed().as_secs_f64());
    // The blend's point counts over the ranks (each rank's search counts its sub-mesh's).
    let blend = crate::validity::blend::BlendInfo {
        reduced_points: sizes[2] as usize,
        target_points: sizes[3] as usize,
        straight_points: sizes[4] as usize,
        ..share.blend
    };
    let space = SpaceCounts {
        control_points: counts[0],
        spline_elements: counts[1],
        q2_elements: counts[2],
        kink_elements: counts[3],
        knot_intervals: share.knot_intervals,
        knot_passes: share.knot_passes,
        features: share.features.map(|mut f| {
            f.feature_vertex_deviation_max /= deviation.diagonal;
            f.planarity_max /= deviation.diagonal;
            f
        }),
    };
    let nonzeros = per_rank.iter().map(|f| f.matrix_nonzeros).sum();
    let n_global = share.local.n_global as usize;
    let outcomes = Outcomes {
        dimension: out.dim,
        elements: n_global,
        order,
        output_nodes: sizes[0] as usize,
        output_elements: n_global,
        boundary_facets: sizes[1] as usize,
        spline: Some(SplineFigures {
            knot_surfaces: share.knot_surfaces,
            ..SplineFigures::blended(
                space,
                (crate::fit::FitSolver::Cg, share.cg, nonzeros),
                blend,
            )
        }),
        snapped: None,
        elastic: None,
        periodic: periodic_report(&share.pairs, &share.output, options, deviation.diagonal),
        input_min_scaled_jacobian: share.input_msj,
        min_scaled_jacobian: min_sj,
        deviation,
        // The distributed job runs on the CPU only.
        gpu: None,
        per_rank: Some(per_rank),
    };
    let report = CurveReport::build(input, options, outcomes, clock.into_timings());
    let mut tag_names = share.local.mesh.tag_names.clone();
    if options.periodic.pyfr_names {
        for (i, p) in share.pairs.iter().enumerate() {
            tag_names.insert(p.master_tag, format!("periodic_{i}_l"));
            tag_names.insert(p.slave_tag, format!("periodic_{i}_r"));
        }
    }
    Ok(Finished {
        tag_names,
        output: share.output,
        report,
    })
}

/// The report's `periodic` (and the seams' certified bound) when the job has pairs: the
/// serial report's fields, the seams `c0` (each side curved on its own under mpirun).
fn periodic_report(
    pairs: &[crate::mesh::periodic::PeriodicPair],
    output: &RankOutput,
    options: &CurveOptions,
    diagonal: f64,
) -> Option<(f64, crate::pipeline::PeriodicReport)> {
    let info = output.images?;
    let report = crate::pipeline::PeriodicReport {
        pairs: pairs.iter().map(|p| p.summary(diagonal)).collect(),
        node_pairs: output
            .periodic
            .iter()
            .map(|l| l.node_pairs.len())
            .sum(),
        max_seam_shift: info.max_shift / diagonal,
        written_mismatch: info.max_mismatch / diagonal,
        recertified_elements: info.recertified,
        seam: "c0",
        seam_c0_reason: Some(
            "under mpirun the seams are not identified in the spline space: each side is curved on its own and made exact images after sampling".into(),
        ),
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
