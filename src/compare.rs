//! The `compare` job: the same mesh curved by every method, side by side, and the interior
//! smoothness measure (docs/compare.md).
//!
//! Input: a linear mesh path and [`CompareOptions`]. Output: a [`CompareReport`] with one
//! [`CompareRow`] per method — straight order-P mesh, IGA with the `position`, `frame` and
//! `smooth` fits, and the elastic analogy inside the `smooth` fit's boundary. A method that fails
//! (e.g. cannot be certified valid) gets a row with its error, not an abort. Nothing is written.
//!
//! **Facet angle jump.** For every interior facet (shared by elements A and B) and every node of
//! the facet's order-P lattice that is not on the facet's own boundary (P ≥ 2), take each element's parametric derivative across the facet
//! (∂x/∂ξ_k for the facet's normal direction k, oriented out of the element): A's outward and
//! B's inward derivative are parallel where the map is C¹ across the facet (also where the two
//! elements' parametrisations differ in speed), and the angle between them is the kink of the
//! mesh line through the facet. The tangential derivatives agree for every conforming (C⁰)
//! mesh, so only the transversal one measures smoothness. Facets are "near the boundary" when
//! either element has a vertex on the boundary, "interior" otherwise.

use crate::elastic::ElasticParams;
use crate::fit::{FitParams, FitTargets, FitWeights, SmoothParams};
use crate::math::lagrange::lagrange_1d;
use crate::mesh::HighOrderMesh;
use crate::mesh::high_order::{Lattice, lattice_point};
use crate::mesh::topology::NONE;
use crate::mesh::{LinearMesh, Topology};
use crate::params::ParamError;
use crate::pipeline::{CurveError, CurveOptions, Curved, Geometry, Method, curve_in_memory};
use rayon::prelude::*;
use serde::Serialize;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// Angle jumps over one set of facets, in degrees.
#[derive(Clone, Copy, Debug, Default, Serialize)]
pub struct AngleStats {
    pub facets: usize,
    /// Facet lattice points measured.
    pub points: usize,
    pub mean_deg: f64,
    pub max_deg: f64,
}

/// The facet angle jump near the boundary and away from it.
#[derive(Clone, Copy, Debug, Default, Serialize)]
pub struct Smoothness {
    pub near_boundary: AngleStats,
    pub interior: AngleStats,
}

#[derive(Clone, Copy, Default)]
struct Acc {
    facets: usize,
    points: usize,
    sum: f64,
    max: f64,
}

impl Acc {
    fn merge(self, o: Acc) -> Acc {
        Acc {
            facets: self.facets + o.facets,
            points: self.points + o.points,
            sum: self.sum + o.sum,
            max: self.max.max(o.max),
        }
    }
    fn stats(self) -> AngleStats {
        AngleStats {
            facets: self.facets,
            points: self.points,
            mean_deg: if self.points > 0 {
                self.sum / self.points as f64
            } else {
                0.0
            },
            max_deg: self.max,
        }
    }
}

/// The facet angle jump of `ho` (element e of `ho` is element e of `mesh`, same vertex ids).
pub fn facet_angle_jumps(mesh: &LinearMesh, topo: &Topology, ho: &HighOrderMesh) -> Smoothness {
    assert_eq!(
        ho.n_elements(),
        mesh.n_elements(),
        "one output element per input element"
    );
    let (d, p) = (ho.dim, ho.order);
    let m = p + 1;
    // L_i'(0) and L_i'(1): derivative across a facet at the lattice ends.
    let mut v = vec![0.0; m];
    let mut ends = [vec![0.0; m], vec![0.0; m]];
    for (s, end) in ends.iter_mut().enumerate() {
        lagrange_1d(p, s as f64, &mut v, end);
    }
    let touches: Vec<bool> = (0..mesh.n_elements())
        .map(|e| {
            mesh.element(e)
                .iter()
                .any(|&v| topo.vertex_on_boundary[v as usize])
        })
        .collect();
    // Interior lattice points of a facet: at its corners (and 3D edges) the neighbours of an
    // irregular vertex meet at angles no map can straighten, so those points are left out.
    if p < 2 {
        return Smoothness::default();
    }
    let per_facet = (p - 1).pow(d as u32 - 1);
    // Lattice points of side `s` (k = s/2 fixed at its end), with the outward derivative.
    let side_points = |e: usize, s: usize| -> Vec<(u32, [f64; 3])> {
        let (k, end) = (s / 2, s % 2);
        let sign = if end == 1 { 1.0 } else { -1.0 };
        let ids = ho.element(e);
        (0..per_facet)
            .map(|q| {
                let f = lattice_point(p - 2, d - 1, q).map(|x| x + 1);
                let mut l: Lattice = [0; 3];
                let mut j = 0;
                for a in 0..d {
                    if a == k {
                        l[a] = end * p;
                    } else {
                        l[a] = f[j];
                        j += 1;
                    }
                }
                let node = |l: Lattice| ids[l[0] + m * (l[1] + m * l[2])] as usize;
                let mut t = [0.0; 3];
                for i in 0..m {
                    let mut li = l;
                    li[k] = i;
                    let x = ho.nodes[node(li)];
                    for c in 0..3 {
                        t[c] += sign * ends[end][i] * x[c];
                    }
                }
                (node(l) as u32, t)
            })
            .collect()
    };
    let (near, inner) = (0..topo.n_facets())
        .into_par_iter()
        .filter(|&f| topo.facet_elements[f][1] != NONE && topo.facet_elements[f][0] != NONE)
        .map(|f| {
            let [a, b] = topo.facet_elements[f].map(|e| e as usize);
            let [sa, sb] = topo.facet_sides[f].map(|s| s as usize);
            let pa = side_points(a, sa);
            let pb = side_points(b, sb);
            let mut acc = Acc {
                facets: 1,
                ..Default::default()
            };
            for (n, ta) in &pa {
                let (_, tb) = pb
                    .iter()
                    .find(|(nb, _)| nb == n)
                    .expect("shared facet node");
                let dot: f64 = (0..3).map(|c| -ta[c] * tb[c]).sum();
                let na = ta.iter().map(|x| x * x).sum::<f64>().sqrt();
                let nb = tb.iter().map(|x| x * x).sum::<f64>().sqrt();
                let angle = (dot / (na * nb)).clamp(-1.0, 1.0).acos().to_degrees();
                acc.points += 1;
                acc.sum += angle;
                acc.max = acc.max.max(angle);
            }
            if touches[a] || touches[b] {
                (acc, Acc::default())
            } else {
                (Acc::default(), acc)
            }
        })
        .reduce(
            || (Acc::default(), Acc::default()),
            |x, y| (x.0.merge(y.0), x.1.merge(y.1)),
        );
    Smoothness {
        near_boundary: near.stats(),
        interior: inner.stats(),
    }
}

/// Options of the `compare` job: `base` supplies order, mesh, line-search and backend options
/// (its geometry, method and fit are set per row).
#[derive(Clone, Debug)]
pub struct CompareOptions {
    pub base: CurveOptions,
    pub elastic: ElasticParams,
}

impl CompareOptions {
    /// Every option of the job: the base options, and the same with the elastic method.
    pub fn check(&self) -> Result<(), ParamError> {
        self.base.check()?;
        CurveOptions {
            method: Method::Elastic(self.elastic),
            ..self.base.clone()
        }
        .check()
    }
}

/// One method's result.
#[derive(Clone, Debug, Serialize)]
pub struct CompareRow {
    /// `straight`, `iga-position`, `iga-frame`, `iga-smooth` or `elastic`.
    pub method: String,
    /// Why the method produced no mesh (nothing else is set then, except `invalid_elements`
    /// when the failure was a validity certificate).
    pub error: Option<String>,
    /// Seconds per stage of the `curve` job (as in its report), and `total`.
    pub timings: BTreeMap<String, f64>,
    /// Seconds of the method's own stages: sampling for `straight`; spline, fit, validity and
    /// sampling for IGA; the straight mesh, elastic solve and its certificate for `elastic`
    /// (not the IGA boundary it starts from, as in the paper's Table 1).
    pub method_seconds: Option<f64>,
    pub total_seconds: Option<f64>,
    pub invalid_elements: Option<usize>,
    pub min_scaled_jacobian: Option<f64>,
    /// Boundary vertex nodes from the input vertices (relative to the diagonal).
    pub boundary_vertex_deviation_max: Option<f64>,
    pub boundary_vertex_deviation_rms: Option<f64>,
    /// Every written boundary node from the input's linear boundary (relative).
    pub boundary_node_distance_max: Option<f64>,
    /// CG iterations of the fit (IGA) or of the elastic solve.
    pub cg_iterations: Option<usize>,
    pub smoothness: Option<Smoothness>,
}

/// The comparison table.
#[derive(Clone, Debug, Serialize)]
pub struct CompareReport {
    pub input: PathBuf,
    pub dimension: usize,
    pub elements: usize,
    pub order: usize,
    /// Knot intervals of the IGA rows' spline space (and of the elastic row's boundary).
    pub knot_intervals: crate::spline::KnotIntervals,
    pub rows: Vec<CompareRow>,
    /// `method_seconds` of `elastic` over that of `iga-smooth` (the boundary they share).
    pub elastic_over_iga_time: Option<f64>,
}

/// Stages that make up each method's own time.
fn method_stages(method: &str) -> &'static [&'static str] {
    match method {
        "straight" => &["sample"],
        "elastic" => &["elastic_sample", "elastic", "elastic_validity"],
        _ => &["spline", "fit", "validity", "sample"],
    }
}

fn row(method: &str, result: Result<Curved, CurveError>) -> CompareRow {
    let mut row = CompareRow {
        method: method.into(),
        error: None,
        timings: BTreeMap::new(),
        method_seconds: None,
        total_seconds: None,
        invalid_elements: None,
        min_scaled_jacobian: None,
        boundary_vertex_deviation_max: None,
        boundary_vertex_deviation_rms: None,
        boundary_node_distance_max: None,
        cg_iterations: None,
        smoothness: None,
    };
    match result {
        Err(e) => {
            if let CurveError::Invalid { count, .. } = &e {
                row.invalid_elements = Some(*count);
            }
            row.error = Some(e.to_string());
        }
        Ok(c) => {
            let r = &c.report;
            row.method_seconds = Some(
                method_stages(method)
                    .iter()
                    .filter_map(|s| r.timings.get(*s))
                    .sum(),
            );
            row.total_seconds = r.timings.get("total").copied();
            row.timings = r.timings.clone();
            row.invalid_elements = Some(r.invalid_elements);
            row.min_scaled_jacobian = Some(r.min_scaled_jacobian);
            row.boundary_vertex_deviation_max = Some(r.boundary_vertex_deviation_max);
            row.boundary_vertex_deviation_rms = Some(r.boundary_vertex_deviation_rms);
            row.boundary_node_distance_max = Some(r.boundary_node_distance_max);
            row.cg_iterations = r.elastic.map(|e| e.cg.iterations).or(r.cg_iterations);
            row.smoothness = Some(facet_angle_jumps(&c.mesh, &c.topo, &c.ho));
        }
    }
    row
}

/// Run every method on `input`.
pub fn compare(input: &Path, options: &CompareOptions) -> Result<CompareReport, CurveError> {
    if options.base.subdivide.is_some() {
        return Err(CurveError::Options(
            "compare measures the order-P elements; --subdivide does not apply".into(),
        ));
    }
    options
        .check()
        .map_err(|e| CurveError::Options(e.to_string()))?;
    let mesh = crate::io::read_mesh(input, &options.base.mesh)?;
    // A bad feature edits file is an input error, not one method's failure.
    if options.base.features.edits.is_some() {
        let topo = crate::mesh::Topology::build(&mesh);
        options.base.features.detect(&mesh, &topo)?;
    }
    let base = &options.base;
    let fitted = |weights: FitWeights, targets: FitTargets, method: Method| CurveOptions {
        geometry: Geometry::SplineFitted,
        method,
        fit: FitParams {
            weights,
            targets,
            ..base.fit.clone()
        },
        ..base.clone()
    };
    let smooth = FitTargets::Smooth(SmoothParams::default());
    let runs: Vec<(&str, CurveOptions)> = vec![
        (
            "straight",
            CurveOptions {
                geometry: Geometry::Straight,
                method: Method::Iga,
                ..base.clone()
            },
        ),
        (
            "iga-position",
            fitted(FitWeights::position(), FitTargets::Chords, Method::Iga),
        ),
        (
            "iga-frame",
            fitted(FitWeights::frame(), FitTargets::Chords, Method::Iga),
        ),
        (
            "iga-smooth",
            fitted(FitWeights::smooth(), smooth, Method::Iga),
        ),
        (
            "elastic",
            fitted(
                FitWeights::smooth(),
                smooth,
                Method::Elastic(options.elastic),
            ),
        ),
    ];
    let rows: Vec<CompareRow> = runs
        .iter()
        .map(|(name, o)| row(name, curve_in_memory(input, o)))
        .collect();
    // A table of failures only is an error, not a comparison.
    if let Some(first) = rows.first().and_then(|r| r.error.clone())
        && rows.iter().all(|r| r.error.is_some())
    {
        return Err(CurveError::Options(format!(
            "every method failed; {}: {first}",
            rows[0].method
        )));
    }
    let seconds = |name: &str| {
        rows.iter()
            .find(|r| r.method == name)
            .and_then(|r| r.method_seconds)
    };
    let elastic_over_iga_time = match (seconds("elastic"), seconds("iga-smooth")) {
        (Some(e), Some(i)) if i > 0.0 => Some(e / i),
        _ => None,
    };
    Ok(CompareReport {
        input: input.to_owned(),
        dimension: mesh.dim,
        elements: mesh.n_elements(),
        order: base.order,
        knot_intervals: base.knots.intervals,
        rows,
        elastic_over_iga_time,
    })
}

impl std::fmt::Display for CompareReport {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        writeln!(
            f,
            "{}: {}D, {} elements, order {}, {} knots",
            self.input.display(),
            self.dimension,
            self.elements,
            self.order,
            match self.knot_intervals {
                crate::spline::KnotIntervals::Uniform => "uniform",
                crate::spline::KnotIntervals::Graded => "graded",
                crate::spline::KnotIntervals::Auto => "auto",
            }
        )?;
        writeln!(
            f,
            "{:<13} {:>9} {:>9} {:>7} {:>8} {:>9} {:>9} {:>6} {:>15} {:>15}",
            "method",
            "method s",
            "total s",
            "invalid",
            "min SJ",
            "vtx dev",
            "node dist",
            "CG it",
            "jump near (°)",
            "jump inner (°)"
        )?;
        let opt = |x: Option<f64>, prec: usize| x.map_or("-".into(), |v| format!("{v:.prec$}"));
        for r in &self.rows {
            let jump = |s: Option<AngleStats>| {
                s.filter(|s| s.points > 0).map_or("-".into(), |s| {
                    format!("{:.2}/{:.1}", s.mean_deg, s.max_deg)
                })
            };
            writeln!(
                f,
                "{:<13} {:>9} {:>9} {:>7} {:>8} {:>9} {:>9} {:>6} {:>15} {:>15}",
                r.method,
                opt(r.method_seconds, 3),
                opt(r.total_seconds, 3),
                r.invalid_elements.map_or("-".into(), |n| n.to_string()),
                opt(r.min_scaled_jacobian, 4),
                r.boundary_vertex_deviation_max
                    .map_or("-".into(), |v| format!("{v:.2e}")),
                r.boundary_node_distance_max
                    .map_or("-".into(), |v| format!("{v:.2e}")),
                r.cg_iterations.map_or("-".into(), |n| n.to_string()),
                jump(r.smoothness.map(|s| s.near_boundary)),
                jump(r.smoothness.map(|s| s.interior)),
            )?;
        }
        writeln!(
            f,
            "(jump: mean/max angle between the elements' transversal derivatives across interior facets)"
        )?;
        writeln!(
            f,
            "(vtx dev: boundary vertex nodes from the input vertices; node dist: every boundary node from the input's linear boundary; both relative to the bounding-box diagonal)"
        )?;
        for r in &self.rows {
            if let Some(e) = &r.error {
                writeln!(f, "{}: failed: {e}", r.method)?;
            } else {
                let stages: Vec<String> = r
                    .timings
                    .iter()
                    .filter(|(k, _)| k.as_str() != "total")
                    .map(|(k, v)| format!("{k} {v:.3}"))
                    .collect();
                writeln!(f, "{} stages (s): {}", r.method, stages.join(", "))?;
            }
        }
        if let Some(ratio) = self.elastic_over_iga_time {
            writeln!(f, "elastic / iga-smooth time: {ratio:.1}x")?;
        }
        Ok(())
    }
}
