//! The `curve` job across MPI ranks (see `docs/distributed.md` for what is distributed and
//! what is not yet).
//!
//! Input: the input mesh path, [`CurveOptions`] (the default IGA path: the certified blend of
//! the least-squares fit, CPU backend) and a [`Comm`]. Output: on rank 0, the curved
//! high-order mesh gathered from the ranks and a [`DistributedReport`]; `None` on the others.
//!
//! Stages per rank: read the whole input and build the topology, features, smooth targets and
//! spline space (replicated: every rank computes the same); partition the elements along a
//! Morton curve ([`super::partition`]); assemble the normal equations over its own elements
//! only ([`crate::fit::partial`]); solve them with the distributed CG ([`super::cg`]); run the
//! certified blend on its own elements, the ranks agreeing on the rejected elements of every
//! round ([`crate::validity::blend::blend_search_shared`]); send its elements' final Bernstein
//! nets to rank 0, which samples them with the serial, entity-based node numbering and writes
//! the file. Invariant: the result equals the serial run's up to the CG tolerance (the
//! distributed CG preconditions with point Jacobi instead of block Jacobi); the blend's
//! factors are the serial search's for the same fitted map.

use super::cg::{Halo, LocalMatrix, pcg};
use super::comm::Comm;
use super::partition::Partition;
use crate::fit::{FitParams, FitTargets};
use crate::io::read_mesh;
use crate::math::BezierElements;
use crate::mesh::Topology;
use crate::pipeline::{CurveError, CurveOptions, CurveReport, Geometry, LineSearchMode, Method};
use crate::quality::sample_det_jacobian;
use crate::sample::{HighOrderMesh, sample};
use crate::spline::{SplineSpace, kinks};
use crate::validity::CpuCertifier;
use crate::validity::blend::{BlendShare, Blended, blend_search_shared};
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

/// [`BlendShare`] over a [`Comm`]: element lists travel as f64 (exact below 2⁵³).
struct CommShare<'a> {
    comm: &'a dyn Comm,
    mine: &'a [usize],
}

impl BlendShare for CommShare<'_> {
    fn mine(&self) -> Option<&[usize]> {
        Some(self.mine)
    }
    fn union(&self, elements: Vec<usize>) -> Vec<usize> {
        let v: Vec<f64> = elements.iter().map(|&e| e as f64).collect();
        let mut all: Vec<usize> = self
            .comm
            .all_gather_f64(&v)
            .concat()
            .into_iter()
            .map(|x| x as usize)
            .collect();
        all.sort_unstable();
        all.dedup();
        all
    }
    fn concat(&self, values: Vec<f64>) -> Vec<f64> {
        self.comm.all_gather_f64(&values).concat()
    }
    fn sum(&self, v: usize) -> usize {
        let mut x = [v as u64];
        self.comm.sum_u64(&mut x);
        x[0] as usize
    }
    fn min(&self, v: f64) -> f64 {
        let mut x = [v];
        self.comm.min_f64(&mut x);
        x[0]
    }
}

/// Element nets gathered on rank 0, in element order.
struct Nets {
    dim: usize,
    nets: Vec<[[f64; 3]; 27]>,
}

impl BezierElements for Nets {
    fn dim(&self) -> usize {
        self.dim
    }
    fn n_elements(&self) -> usize {
        self.nets.len()
    }
    fn bezier_net(&self, e: usize) -> [[f64; 3]; 27] {
        self.nets[e]
    }
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
    let mut timings = BTreeMap::new();
    let mut t = Instant::now();
    let mut lap = |name: &str, timings: &mut BTreeMap<String, f64>| {
        timings.insert(name.to_string(), t.elapsed().as_secs_f64());
        t = Instant::now();
    };
    // Replicated setup: the same on every rank.
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
    let features = Some(options.features.detect(&mesh, &topo)?).filter(|f| !f.is_empty());
    let used = features.as_ref().filter(|_| !options.features.ignore);
    let crease = used.map_or_else(Vec::new, |f| f.crease_elements(&topo));
    let fit_params = FitParams {
        features: used.cloned().map(std::sync::Arc::new),
        ..options.fit.clone()
    };
    let kinks = match options.fit.targets {
        FitTargets::Smooth(p) => {
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
    let targets = crate::fit::smooth_targets(&mesh, &topo, &fit_params);
    let blend_targets = match &targets {
        None => crate::fit::smooth_targets(
            &mesh,
            &topo,
            &FitParams {
                targets: FitTargets::Smooth(Default::default()),
                ..fit_params.clone()
            },
        ),
        Some(_) => None,
    };
    let target_map = crate::fit::TargetMap {
        mesh: &mesh,
        topo: &topo,
        smooth: targets.as_ref().or(blend_targets.as_ref()),
    };
    let demote = vec![false; mesh.n_elements()];
    let mut s = SplineSpace::build_with_q2(
        &mesh,
        &topo,
        &[
            (&crease, crate::spline::Q2Reason::FeatureCrease),
            (&kinks.elements, crate::spline::Q2Reason::BoundaryKink),
            (&demote, crate::spline::Q2Reason::InvalidSplineMap),
        ],
    );
    lap("spline", &mut timings);

    // The partition and the control points every rank touches.
    let partition = Partition::morton(&mesh, size);
    let mine = &partition.elements[rank];
    let mut touched: Vec<Vec<u32>> = vec![Vec::new(); size];
    let mut rows = crate::spline::ElementRows::default();
    for e in 0..mesh.n_elements() {
        s.extraction.rows(e, &mut rows);
        touched[partition.part[e] as usize].extend_from_slice(&rows.cols);
    }
    for list in &mut touched {
        list.sort_unstable();
        list.dedup();
    }
    let halo = Halo::new(rank, &touched, s.n_control_points());
    drop(touched);
    lap("partition", &mut timings);

    // This rank's share of the fit, solved together.
    let mut sys = crate::fit::partial::partial_normal_equations(
        &s,
        &mesh,
        &topo,
        &fit_params,
        targets.as_ref(),
        mine,
    );
    if let Some(d) = &sys.scale {
        sys.matrix.scale_symmetric(d);
        for (r, &d) in sys.rhs.iter_mut().zip(d) {
            *r = r.map(|x| d * x);
        }
    }
    let local = LocalMatrix::new(&sys.matrix, &halo);
    let b: Vec<[f64; 3]> = halo.global.iter().map(|&g| sys.rhs[g as usize]).collect();
    let scale = sys.scale.take();
    drop(sys);
    lap("fit_assembly", &mut timings);
    let mut delta = vec![[0.0; 3]; halo.len()];
    let cg = pcg(comm, &halo, &local, &b, &mut delta, &fit_params.cg).map_err(|source| {
        CurveError::Solve {
            input: input.to_owned(),
            source,
        }
    })?;
    lap("fit_cg", &mut timings);
    let bytes_fit = comm.bytes_sent();
    let mut c_star = s.control_points.clone();
    for (i, &g) in halo.global.iter().enumerate() {
        let g = g as usize;
        let d = scale.as_ref().map_or(1.0, |d| d[g]);
        for k in 0..3 {
            c_star[g][k] += d * delta[i][k];
        }
    }
    if let Some(f) = used {
        crate::fit::features::project_onto_planes(&s, &topo, f, &mut c_star);
    }
    s.control_points = c_star;

    // The certified blend, judged per rank.
    let blend_params = options
        .line_search
        .blend(options.line_search_mode == LineSearchMode::Global);
    let mut blended = Blended::new(&mesh, &target_map, &s, &mesh, &topo, Vec::new());
    let share = CommShare { comm, mine };
    let blend_info = blend_search_shared(&CpuCertifier, &mut blended, &blend_params, &share)
        .map_err(|source| CurveError::Blend {
            input: input.to_owned(),
            source,
        })?;
    lap("validity", &mut timings);
    let bytes_validity = comm.bytes_sent() - bytes_fit;

    // Nets to rank 0, figures to rank 0.
    let np = if mesh.dim == 2 { 9 } else { 27 };
    let nets: Vec<f64> = mine
        .iter()
        .flat_map(|&e| {
            let n = blended.bezier_net(e);
            n[..np].iter().flatten().copied().collect::<Vec<_>>()
        })
        .collect();
    let gathered = comm.gather_f64(0, &nets);
    drop(nets);
    lap("gather", &mut timings);
    let figures = RankFigures {
        rank,
        elements: mine.len(),
        control_points: halo.len(),
        owned_control_points: halo.owned.iter().filter(|&&o| o).count(),
        shared_control_points: halo.shared(),
        neighbours: halo.neighbours.len(),
        matrix_nonzeros: local.nonzeros(),
        bytes_sent: comm.bytes_sent(),
        bytes_fit,
        bytes_validity,
        bytes_gather: comm.bytes_sent() - bytes_fit - bytes_validity,
        peak_memory_bytes: peak_memory_bytes(),
        timings: timings.clone(),
    };
    let all_figures = gather_figures(comm, &figures);
    let Some(gathered) = gathered else {
        return Ok(None);
    };

    // Rank 0: the serial sampling, numbering and checks on the gathered nets.
    let mut net_of = vec![[[0.0; 3]; 27]; mesh.n_elements()];
    for (q, flat) in gathered.iter().enumerate() {
        for (k, &e) in partition.elements[q].iter().enumerate() {
            for i in 0..np {
                net_of[e][i].copy_from_slice(&flat[3 * (np * k + i)..3 * (np * k + i) + 3]);
            }
        }
    }
    drop(gathered);
    let source = Nets {
        dim: mesh.dim,
        nets: net_of,
    };
    let mut ho = sample(&source, &mesh, &topo, order);
    if options.subdivide.is_some() {
        ho = ho.subdivided();
    }
    lap("sample", &mut timings);
    let snapped = options.snap_boundary.then(|| {
        crate::pipeline::snap_boundary(&mesh, &topo, &mut ho, options.line_search.certificate_depth)
    });
    let quality = sample_det_jacobian(&ho);
    let min_sj = quality
        .iter()
        .map(|q| q.min_scaled_jacobian)
        .fold(f64::INFINITY, f64::min);
    let invalid: Vec<usize> = (0..quality.len())
        .filter(|&e| !(quality[e].min_det_jacobian > 0.0))
        .collect();
    if !invalid.is_empty() {
        return Err(CurveError::Invalid {
            input: input.to_owned(),
            what: "sampled output".into(),
            count: invalid.len(),
            first: invalid
                .iter()
                .take(8)
                .map(|e| e.to_string())
                .collect::<Vec<_>>()
                .join(", "),
        });
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
        elastic: None,
        // The distributed job runs on the CPU only.
        gpu_fallbacks: None,
        output_nodes: ho.nodes.len(),
        output_elements: ho.n_elements(),
        boundary_facets: ho.n_boundary(),
        control_points: s.n_control_points(),
        spline_elements: s.n_spline_elements(),
        q2_elements: s.n_q2_elements(),
        demoted_elements: 0,
        kink_elements: s
            .classes
            .iter()
            .filter(|c| {
                **c == crate::spline::ElementClass::Q2(crate::spline::Q2Reason::BoundaryKink)
            })
            .count(),
        snapped_boundary_vertices: snapped,
        features: features.as_ref().map(|f| {
            let (vertex, planarity) = f.deviations(&mesh, &ho);
            crate::mesh::features::FeatureReport {
                found: f.summary(&options.features.params, &topo),
                feature_vertex_deviation_max: vertex,
                planarity_max: planarity,
            }
        }),
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
            timings: STAGES
                .iter()
                .zip(&v[11..])
                .map(|(s, &t)| (s.to_string(), t))
                .collect(),
        })
        .collect()
}
