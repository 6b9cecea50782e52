//! The `curve` job across MPI ranks (see `docs/distributed.md` for what is distributed and
//! what is not yet).
//!
//! Input: the input mesh path (binary MSH 4.1), [`CurveOptions`] (the default IGA path: the
//! certified blend of the least-squares fit, CPU backend) and a [`Comm`]. Output: on rank 0,
//! the curved high-order mesh gathered from the ranks and a [`DistributedReport`]; `None` on
//! the others.
//!
//! Stages per rank: read its contiguous run of the file's elements and [`GHOST_DEPTH`] vertex
//! rings of ghosts by offsets ([`super::read`]); build the topology, features, smooth targets
//! and spline space on that sub-mesh with the serial stage functions
//! (`pipeline::spline::SplineSetup`); agree on the shared control points by keys of
//! global entity ids ([`super::local`]); assemble the normal equations over its own elements
//! with the whole mesh's size levels ([`crate::fit::partial`]); solve them with the
//! distributed block-Jacobi CG ([`super::cg`]); run the certified blend on its own elements,
//! the ranks agreeing on the rejected elements of every round in global ids
//! ([`crate::validity::blend::blend_search_shared`]); send its elements' final Bernstein nets
//! to rank 0, which reads the linear mesh, samples the nets with the serial, entity-based
//! node numbering and writes the file. Invariant: the result equals the serial run's up to
//! the CG tolerance (the block-Jacobi aggregates differ from the serial solver's); the
//! blend's factors are the serial search's for the same fitted map.

use super::cg::{Halo, LocalMatrix, pcg};
use super::comm::Comm;
use super::local::{GHOST_DEPTH, LocalShare};
use super::read::LocalMesh;
use super::share::read_share;
use crate::io::read_mesh;
use crate::math::{BezierElements, BezierNet};
use crate::mesh::Topology;
use crate::pipeline::spline::SplineSetup;
use crate::pipeline::{
    CurveError, CurveOptions, CurveReport, Geometry, Job, LineSearchMode, Method,
};
use crate::sample::{HighOrderMesh, sample};
use crate::spline::{ElementClass, Q2Reason};
use crate::validity::CpuCertifier;
use crate::validity::blend::{Blended, blend_search_shared};
use serde::Serialize;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// One rank's share of the work and of the communication.
#[derive(Clone, Debug, Default, Serialize)]
pub struct RankFigures {
    pub rank: usize,
    /// Elements this rank assembles, certifies and sends.
    pub elements: usize,
    /// Ghost elements it read and built its setup on besides its own.
    pub ghost_elements: usize,
    /// Control points its elements touch (the rows it holds), those it owns (counted in dot
    /// products), and those it shares with other ranks (its halo).
    pub control_points: usize,
    pub owned_control_points: usize,
    pub shared_control_points: usize,
    /// Ranks it exchanges halo values with.
    pub neighbours: usize,
    /// Stored entries of its share of K (local numbering).
    pub matrix_nonzeros: usize,
    /// Bytes it sent (halo exchanges, reductions, gathers), in all and by stage: the fit
    /// (CG halo exchanges and reductions), the certified blend (rejected elements, counts),
    /// and the nets sent to rank 0.
    pub bytes_sent: u64,
    pub bytes_fit: u64,
    pub bytes_validity: u64,
    pub bytes_gather: u64,
    /// Peak resident memory of the process (VmHWM), bytes.
    pub peak_memory_bytes: u64,
    /// Seconds per stage.
    pub timings: BTreeMap<String, f64>,
}

/// The report of a distributed `curve`: the serial report's figures for the whole mesh and
/// every rank's share.
#[derive(Clone, Debug, Serialize)]
pub struct DistributedReport {
    #[serde(flatten)]
    pub curve: CurveReport,
    pub ranks: usize,
    pub per_rank: Vec<RankFigures>,
}

/// What rank 0 holds at the end.
pub struct Gathered {
    pub mesh: HighOrderMesh,
    pub report: DistributedReport,
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
    Ok(())
}

/// Peak resident memory of this process (Linux `VmHWM`), bytes; 0 where unknown.
pub fn peak_memory_bytes() -> u64 {
    std::fs::read_to_string("/proc/self/status")
        .ok()
        .and_then(|s| {
            s.lines()
                .find(|l| l.starts_with("VmHWM:"))
                .and_then(|l| l.split_whitespace().nth(1)?.parse::<u64>().ok())
        })
        .map_or(0, |kb| kb * 1024)
}

/// Element nets gathered on rank 0, in element order (the ranks' runs of elements follow
/// each other in file order), `np` points of 3 doubles each.
struct Nets {
    dim: usize,
    np: usize,
    flat: Vec<f64>,
    /// Position in `flat` of each element's net (the ranks' nets come in rank order, each
    /// rank's Morton part in increasing element order): an index rather than a reordered copy,
    /// which would double rank 0's largest buffer.
    row: Vec<u32>,
}

impl BezierElements for Nets {
    fn dim(&self) -> usize {
        self.dim
    }
    fn n_elements(&self) -> usize {
        self.flat.len() / (3 * self.np)
    }
    fn bezier_net(&self, e: usize) -> BezierNet {
        let mut n = [[0.0; 3]; 27];
        let e = self.row[e] as usize;
        let x = &self.flat[3 * self.np * e..3 * self.np * (e + 1)];
        for (i, p) in x.chunks_exact(3).enumerate() {
            n[i].copy_from_slice(p);
        }
        n
    }
}

/// The position of each element's net among the gathered ones, from the gathered ids.
fn rows_of(ids: &[f64]) -> Vec<u32> {
    let mut row = vec![0u32; ids.len()];
    for (i, &g) in ids.iter().enumerate() {
        row[g as usize] = i as u32;
    }
    row
}

/// Seconds per stage, by name.
struct Laps {
    t: Instant,
    timings: BTreeMap<String, f64>,
}

impl Laps {
    fn lap(&mut self, name: &str) {
        self.timings
            .insert(name.to_string(), self.t.elapsed().as_secs_f64());
        self.t = Instant::now();
    }
}

/// What a rank has after its share of the setup, fit and blend.
struct Share {
    local: LocalMesh,
    cg: crate::solve::CgInfo,
    blend: crate::validity::blend::BlendInfo,
    /// Own elements' final nets, flattened (3^d points × 3 doubles each).
    nets: Vec<f64>,
    /// Own control points (counted once over the ranks), spline, Q2 and kink elements.
    counts: [usize; 4],
    input_msj: f64,
    halo: Halo,
    nonzeros: usize,
    bytes_fit: u64,
    bytes_validity: u64,
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

/// This rank's share of the fit: its rows of the normal equations with the whole mesh's size
/// levels, the scaling agreed over the halo, the distributed block-Jacobi CG, and the fitted
/// control points (projected onto planar patches) in `s`. Returns the CG's figures and the
/// local matrix's stored entries.
#[allow(clippy::too_many_arguments)]
fn fit_share(
    comm: &dyn Comm,
    input: &Path,
    local: &LocalMesh,
    topo: &Topology,
    setup: &SplineSetup,
    s: &mut crate::spline::SplineSpace,
    halo: &Halo,
    mine: &[usize],
    laps: &mut Laps,
) -> Result<(crate::solve::CgInfo, usize), CurveError> {
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
    let k = LocalMatrix::new(&sys.matrix, halo);
    let b: Vec<[f64; 3]> = halo.global.iter().map(|&g| sys.rhs[g as usize]).collect();
    let scale = sys.scale.take();
    drop(sys);
    laps.lap("fit_assembly");
    let mut delta = vec![[0.0; 3]; halo.len()];
    let cg = pcg(comm, halo, &k, &b, &mut delta, &fit_params.cg).map_err(|source| {
        CurveError::Solve {
            input: input.to_owned(),
            source,
        }
    })?;
    laps.lap("fit_cg");
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

/// This rank's read, setup, fit and certified blend (see the module docs).
fn run_share(
    comm: &dyn Comm,
    input: &Path,
    options: &CurveOptions,
    laps: &mut Laps,
) -> Result<Share, CurveError> {
    let local = read_share(comm, input, GHOST_DEPTH, &options.mesh)?;
    laps.lap("read");
    let mesh = &local.mesh;
    let topo = local_topology(input, &local)?;
    laps.lap("topology");
    let mut msj = [mesh.min_scaled_jacobian().map_or(f64::INFINITY, |m| m.0)];
    comm.min_f64(&mut msj);
    let executor = crate::executor::executor(&options.backend);
    let job = Job {
        input,
        options,
        mesh,
        topo: &topo,
        executor: executor.as_ref(),
    };
    let setup = SplineSetup::new(&job)?;
    let mut s = setup.build(&job, &[]);
    laps.lap("spline");
    let halo = super::local::halo(comm, &local, &topo, &s);
    let bytes_partition = comm.bytes_sent();
    laps.lap("partition");

    let mine: Vec<usize> = (0..local.n_owned).collect();
    let (cg, nonzeros) = fit_share(
        comm, input, &local, &topo, &setup, &mut s, &halo, &mine, laps,
    )?;
    let bytes_fit = comm.bytes_sent() - bytes_partition;

    // The certified blend, each rank judging its own elements.
    let blend_params = options
        .line_search
        .blend(options.line_search_mode == LineSearchMode::Global);
    let target_map = setup.target_map(&job);
    let mut blended = Blended::new(mesh, &target_map, &s, mesh, &topo, Vec::new());
    let share = LocalShare {
        comm,
        mine: &mine,
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
    let blend = blend_search_shared(&CpuCertifier, &mut blended, &blend_params, &share).map_err(
        |source| CurveError::Blend {
            input: input.to_owned(),
            source,
        },
    )?;
    drop(share);
    laps.lap("validity");
    let bytes_validity = comm.bytes_sent() - bytes_fit - bytes_partition;
    let np = if mesh.dim == 2 { 9 } else { 27 };
    let nets: Vec<f64> = mine
        .iter()
        .flat_map(|&e| {
            let n = blended.bezier_net(e);
            n[..np].iter().flatten().copied().collect::<Vec<_>>()
        })
        .collect();
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
    Ok(Share {
        local,
        cg,
        blend,
        nets,
        counts,
        input_msj: msj[0],
        halo,
        nonzeros,
        bytes_fit,
        bytes_validity,
    })
}

/// Run the distributed `curve` job on every rank of `comm` (see the module docs).
pub fn curve(
    comm: &dyn Comm,
    input: &Path,
    options: &CurveOptions,
) -> Result<Option<Gathered>, CurveError> {
    check_supported(options)?;
    // The serial job's option checks (elastic is refused above, so no elastic parameters).
    let (order, _) = crate::pipeline::check_options(options)?;
    let (rank, size) = (comm.rank(), comm.size());
    let start = Instant::now();
    let mut laps = Laps {
        t: Instant::now(),
        timings: BTreeMap::new(),
    };
    let share = run_share(comm, input, options, &mut laps)?;
    let mut counts = share.counts.map(|c| c as u64);
    comm.sum_u64(&mut counts);
    let bytes_before = comm.bytes_sent();
    let gathered = comm.gather_f64(0, &share.nets);
    // The ranks own Morton parts, not runs of the file: their global ids put the nets back in
    // the file's order.
    let own_ids: Vec<f64> = share.local.global_element[..share.local.n_owned]
        .iter()
        .map(|&g| g as f64)
        .collect();
    let gathered_ids = comm.gather_f64(0, &own_ids);
    laps.lap("gather");
    let figures = RankFigures {
        rank,
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
        bytes_gather: comm.bytes_sent() - bytes_before,
        peak_memory_bytes: peak_memory_bytes(),
        timings: laps.timings.clone(),
    };
    let Share {
        cg,
        blend: blend_info,
        input_msj,
        ..
    } = share;
    let all_figures = gather_figures(comm, &figures);
    let (Some(gathered), Some(ids)) = (gathered, gathered_ids) else {
        return Ok(None);
    };
    let row = rows_of(&ids);
    drop(ids);

    // Rank 0: the serial sampling, numbering and checks on the gathered nets.
    let mesh = read_mesh(input, &options.mesh)?;
    let topo = Topology::build(&mesh);
    let source = Nets {
        dim: mesh.dim,
        np: if mesh.dim == 2 { 9 } else { 27 },
        flat: gathered,
        row,
    };
    let mut ho = sample(&source, &mesh, &topo, order);
    drop(source);
    if options.subdivide.is_some() {
        ho = ho.subdivided();
    }
    laps.lap("sample");
    let snapped = options.snap_boundary.then(|| {
        crate::pipeline::snap_boundary(&mesh, &topo, &mut ho, options.line_search.certificate_depth)
    });
    let executor = crate::executor::executor(&options.backend);
    let job = Job {
        input,
        options,
        mesh: &mesh,
        topo: &topo,
        executor: executor.as_ref(),
    };
    let (min_sj, deviation) = crate::pipeline::quality_stage(&job, &ho)?;
    laps.lap("quality");
    // Rank 0's peak includes the sampling and checks of the whole output.
    let mut all_figures = all_figures;
    all_figures[0].peak_memory_bytes = peak_memory_bytes();
    let mut timings = laps.timings;
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
        elastic: None,
        // The distributed job runs on the CPU only.
        gpu_fallbacks: None,
        output_nodes: ho.nodes.len(),
        output_elements: ho.n_elements(),
        boundary_facets: ho.n_boundary(),
        control_points: counts[0] as usize,
        spline_elements: counts[1] as usize,
        q2_elements: counts[2] as usize,
        demoted_elements: 0,
        kink_elements: counts[3] as usize,
        snapped_boundary_vertices: snapped,
        // The feature summary needs every rank's patches; not gathered yet.
        features: None,
        fit_weights: Some(options.fit.weights),
        fit_targets: Some(options.fit.targets),
        cg_iterations: Some(cg.iterations),
        matrix_nonzeros: Some(all_figures.iter().map(|f| f.matrix_nonzeros).sum()),
        cg_rel_residual: Some(cg.rel_residual),
        line_search_mode: options.line_search_mode,
        line_search_alpha: Some(0.5 * blend_info.min_factor),
        invalid_at_full_step: blend_info.invalid_at_full_step,
        damped_control_points: blend_info.reduced_points,
        line_search: None,
        reduced_elements: blend_info.reduced_elements,
        min_det_jacobian_bound: Some(blend_info.min_det_lower_bound),
        blend: Some(blend_info),
        energy: None,
        energy_skipped: None,
        invalid_elements: 0,
        input_min_scaled_jacobian: input_msj,
        min_scaled_jacobian: min_sj,
        bounding_box_diagonal: deviation.diagonal,
        boundary_vertex_deviation_max: deviation.vertex_max,
        boundary_vertex_deviation_rms: deviation.vertex_rms,
        boundary_node_distance_max: deviation.node_max,
        boundary_sample_distance_max: deviation.sample_max,
        timings,
        backend: "cpu".into(),
        adapter: None,
        gpu_precision: None,
    };
    Ok(Some(Gathered {
        mesh: ho,
        report: DistributedReport {
            curve: report,
            ranks: size,
            per_rank: all_figures,
        },
    }))
}

/// Stages whose seconds are reported per rank.
const STAGES: [&str; 8] = [
    "read",
    "topology",
    "spline",
    "partition",
    "fit_assembly",
    "fit_cg",
    "validity",
    "gather",
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
        STAGES
            .iter()
            .map(|s| f.timings.get(*s).copied().unwrap_or(0.0)),
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
            timings: STAGES
                .iter()
                .zip(&v[12..])
                .map(|(s, &t)| (s.to_string(), t))
                .collect(),
        })
        .collect()
}
