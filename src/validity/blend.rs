//! Certified blend of the straight-sided elevation, the fit's target map and the fitted map.
//!
//! Input: per element three conforming quadratic Bernstein nets: S_e, the input's multilinear
//! map elevated to quadratic (the straight-sided elevation, certified valid for every valid
//! input); T_e, the fit's targets (`crate::fit::TargetMap`: S plus the smooth boundary's
//! curvature carried into the layers next to it, C⁰); F_e, the fitted spline map (C¹ where the
//! space is). Every Bernstein point of a quadratic element sits on one mesh entity (vertex,
//! edge, face or cell) and is shared by all elements on it. Each entity n gets one factor
//! t_n ∈ [0, 2] ([`entity_ids`]) on the path S → T → F:
//!
//!   B_e\[i\] = T + (t − 1)(F − T) for t ≥ 1,   S + t (T − S) for t ≤ 1,   t = t_n(i),
//!
//! so the blend is conforming for any factors; t = 2 is the fitted map, 1 the target map, 0 the
//! straight elevation.
//!
//! [`blend_search`] starts from t = 2 and accepts an element when (validity) its certified lower
//! bound of det J exceeds `min_det_fraction` × the straight element's and (quality) its
//! Jacobian ratio bound r_B (a certified lower bound of min det J over a certified upper bound
//! of max det J, both refined by subdivision until the test is decided,
//! [`super::certify_ratio`]) is at least max(q_min · r_S, q_p · min(r_S, P)), r_S the
//! straight element's ratio (from its corners) and P the 1st percentile of r_S over the mesh.
//! Every accepted element then has r_B ≥ q_min · r_S, so the mesh's smallest ratio is at least
//! q_min × the straight mesh's; and an element below q_p · P has r_S < P, which only 1 % of
//! the elements have, so the 1st percentile is at least q_p × the straight mesh's.
//! Its smallest scaled Jacobian over the lattice {0, ¼, ½, ¾, 1}^d must also be at least
//! q_min · s_S, s_S the straight element's over the same lattice (det J alone does not see a
//! thin cell sheared along its length); these are the element rules. Once no element is
//! rejected by them, the search goes on from its factors with the floor too: the scaled
//! Jacobian at least max(q_min · s_S, q_p · min(s_S, P_s)), P_s the 1st percentile of s_S
//! over the mesh. By the ratio's argument every element then keeps at least q_p × the
//! straight mesh's smallest scaled Jacobian, and the 1st percentile keeps q_p × the straight
//! mesh's. Holding an element back to its floor moves the points it shares with neighbours
//! whose floor may be lower (a corner cell of an O-grid next to cells of a high s_S), so in
//! phase 2 an element's scaled Jacobian must also stay at least min(its value where phase 1
//! ended, m), m the smallest such value around the elements the floor first rejects: the
//! floor never lowers the mesh's smallest scaled Jacobian below phase 1's (m is at least
//! that; an element back at its straight elevation, accepted as ever, keeps s_S). What is
//! guaranteed: the blended map's scaled Jacobian at every point of that
//! lattice is at least the targets (sampled there: `floor` accepts without sampling only
//! where a certified lower bound over the whole element reaches them).
//! The spline passes (`pipeline::passes`) weigh the elements held back under the element
//! rules ([`BlendInfo::reduced_before_floor`]), not the floor's: the floor binds where the
//! straight mesh's own shape is poorest (the corners of a uniform O-grid cylinder), which no
//! choice of knots, weights or demotion is for.
//! The factors of the entities of rejected elements are halved towards 1 (twice, then set
//! to 1: the target map), then towards 0 (the straight elevation, at most `max_bisections`
//! halvings); global mode bisects one factor for the whole mesh instead. An element whose
//! factors are all 0 is its straight elevation, which is accepted, so the search always ends
//! with every element certified: the guarantee holds for every input whose straight
//! elevation is certified valid, whatever the fit does.

mod entities;
mod floor;
mod shape;

pub use entities::{EntityIds, entity_ids};
use floor::StraightScaledJacobians;
use shape::{corner_ratio, hadamard_upper};
pub use shape::{fine_lattice_scaled_jacobian, lattice_scaled_jacobian, max_det_bound};

use super::{Certifier, DetBounds, certify_ratio, certify_screened, det_jacobian_bernstein};
use crate::math::bernstein::net_len;
use crate::math::linalg::DVec3;
use crate::math::{BezierElements, BezierNet};
use crate::mesh::{LinearMesh, Topology};
use rayon::prelude::*;
use std::sync::OnceLock;

/// Bernstein nets, 9 (2D) or 27 (3D) points, index 9z + 3y + x.
pub type Net = BezierNet;

/// Parameters of [`blend_search`].
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct BlendParams {
    /// Halvings of a factor towards the straight elevation before it is set to 0.
    pub max_bisections: usize,
    /// Subdivision depth of the Bernstein certificate.
    pub certificate_depth: usize,
    /// Accept an element only when its certified lower bound of det J exceeds this fraction of
    /// the straight element's.
    pub min_det_fraction: f64,
    /// q_min: every element keeps at least this fraction of its straight Jacobian ratio
    /// (0: no quality test).
    pub min_quality_fraction: f64,
    /// q_p: elements keep at least this fraction of min(their straight ratio, the straight
    /// mesh's 1st percentile), and the same of the scaled Jacobian.
    pub percentile_quality_fraction: f64,
    /// One factor for the whole mesh (the paper's bisection) instead of one per entity.
    pub global: bool,
    /// Apply the scaled Jacobian's floor after the element rules (phase 2 of the search).
    pub scaled_jacobian_floor: bool,
}

impl Default for BlendParams {
    fn default() -> Self {
        BlendParams {
            max_bisections: 6,
            certificate_depth: 6,
            min_det_fraction: 0.1,
            min_quality_fraction: 0.55,
            percentile_quality_fraction: 0.85,
            global: false,
            scaled_jacobian_floor: true,
        }
    }
}

/// An element whose curving was reduced.
#[deny(missing_docs)]
#[derive(Clone, Debug, serde::Serialize)]
pub struct ReducedElement {
    /// Element index (0-based, input order).
    pub element: usize,
    /// Centroid of the input element.
    pub centroid: [f64; 3],
    /// Smallest factor on its Bernstein points (2 fitted, 1 target map, 0 straight).
    pub min_factor: f64,
    /// Largest distance by which a Bernstein point was held back from the fitted map,
    /// relative to the element's shortest edge.
    pub withheld: f64,
}

/// What [`blend_search`] did.
#[deny(missing_docs)]
#[derive(Clone, Debug, Default, serde::Serialize)]
pub struct BlendInfo {
    /// Elements not certified valid at the full fit.
    pub invalid_at_full_step: usize,
    /// Elements certified valid at the full fit but below the quality bound.
    pub poor_at_full_step: usize,
    /// The straight mesh's smallest Jacobian ratio (from element corners).
    pub straight_ratio_min: f64,
    /// The straight mesh's 1st-percentile Jacobian ratio (from element corners).
    pub straight_ratio_p1: f64,
    /// Rounds of reduction.
    pub rounds: usize,
    /// Elements with a point held back from the fitted map.
    pub reduced_elements: usize,
    /// Of those, the elements held back before the scaled Jacobian's floor was applied (by
    /// the element rules: det J, the Jacobian ratio's rule and q_min × the straight scaled
    /// Jacobian): the count the spline passes weigh (`pipeline::passes`).
    pub reduced_before_floor: usize,
    /// Shared Bernstein points held back from the fitted map (factor < 2).
    pub reduced_points: usize,
    /// Of those, points at or below the target map (factor ≤ 1).
    pub target_points: usize,
    /// Of those, points back at the straight elevation (factor 0).
    pub straight_points: usize,
    /// Smallest factor (2 when nothing was reduced).
    pub min_factor: f64,
    /// The reduced elements with the largest withheld displacement (at most 10).
    pub worst: Vec<ReducedElement>,
    /// Smallest certified lower bound of det J over the mesh.
    pub min_det_lower_bound: f64,
}

/// Why the blend cannot be certified.
#[derive(Clone, Debug, thiserror::Error)]
pub enum BlendError {
    #[error(
        "{count} input element(s) (first: {}) are not valid: det J of the multilinear element is not certified positive inside",
        first.iter().map(|e| e.to_string()).collect::<Vec<_>>().join(", ")
    )]
    StraightInvalid { count: usize, first: Vec<usize> },
}

/// The blended mesh.
pub struct Blended<'a> {
    pub straight: &'a (dyn BezierElements + 'a),
    pub target: &'a (dyn BezierElements + 'a),
    pub fitted: &'a (dyn BezierElements + 'a),
    pub ids: EntityIds<'a>,
    /// The elements' straight geometry (the shapes the quality tests compare with): the
    /// entities' mesh unless [`Blended::with_geometry`] says otherwise.
    pub geometry: &'a LinearMesh,
    /// One factor per entity; empty means 2 (the fitted map) everywhere.
    pub factors: Vec<f32>,
    /// Elements with a factor below 2 on one of their points.
    reduced: Vec<bool>,
    /// Each element's straight, target and fitted nets, computed when first blended: the
    /// search blends a rejected element's neighbourhood again every round, and the target
    /// map's smooth corrections and the spline's evaluation cost more than the blend itself.
    references: NetCache,
}

/// The straight, target and fitted nets a [`Blended`] computed (only those of the elements it
/// blended with a reduced factor), to hand to a later [`Blended`] of the same three maps
/// ([`Blended::with_cache`]): sampling the certified blend then costs no target-map
/// corrections again.
pub struct NetCache(Vec<OnceLock<Box<(Net, Net, Net)>>>);

/// Factor of the fitted map.
pub const FITTED: f32 = 2.0;

/// Elements judged together in one pass of the search (their nets held at once).
const JUDGE_CHUNK: usize = 1 << 14;

impl<'a> Blended<'a> {
    /// The blend with the factors `factors` (empty: the fitted map).
    pub fn new(
        straight: &'a (dyn BezierElements + 'a),
        target: &'a (dyn BezierElements + 'a),
        fitted: &'a (dyn BezierElements + 'a),
        mesh: &'a LinearMesh,
        topo: &'a Topology,
        factors: Vec<f32>,
    ) -> Self {
        // An empty cache fits no element count but 0: `with_cache` makes a fresh one.
        let none = NetCache(Vec::new());
        Self::with_cache(straight, target, fitted, mesh, topo, factors, none)
    }

    /// The elements' straight geometry is `geometry`'s, while the factors stay on the
    /// entities of the mesh given to [`Blended::new`] (a periodic mesh glued across its seams,
    /// whose image-side elements have their masters' vertices).
    pub fn with_geometry(mut self, geometry: &'a LinearMesh) -> Self {
        self.geometry = geometry;
        self
    }

    /// [`Blended::new`] starting from the nets `cache` that a blend of the same straight,
    /// target and fitted maps computed ([`Blended::into_cache`]); a cache of another element
    /// count is not used.
    pub fn with_cache(
        straight: &'a (dyn BezierElements + 'a),
        target: &'a (dyn BezierElements + 'a),
        fitted: &'a (dyn BezierElements + 'a),
        mesh: &'a LinearMesh,
        topo: &'a Topology,
        factors: Vec<f32>,
        cache: NetCache,
    ) -> Self {
        let n = fitted.n_elements();
        let references = if cache.0.len() == n {
            cache
        } else {
            NetCache((0..n).map(|_| OnceLock::new()).collect())
        };
        let mut b = Blended {
            straight,
            target,
            fitted,
            ids: EntityIds::new(mesh, topo),
            geometry: mesh,
            factors,
            reduced: Vec::new(),
            references,
        };
        b.refresh();
        b
    }

    /// The nets computed so far, for a later blend of the same maps.
    pub fn into_cache(self) -> NetCache {
        self.references
    }

    fn points(&self) -> usize {
        net_len(self.fitted.dim())
    }

    fn refresh(&mut self) {
        let np = self.points();
        self.reduced = if self.factors.is_empty() {
            Vec::new()
        } else {
            (0..self.fitted.n_elements())
                .into_par_iter()
                .map(|e| {
                    self.ids.of(e)[..np]
                        .iter()
                        .any(|&id| self.factors[id as usize] < FITTED)
                })
                .collect()
        };
    }

    /// Whether element `e` differs from the fitted map.
    pub fn is_reduced(&self, e: usize) -> bool {
        self.reduced.get(e).copied().unwrap_or(false)
    }

    /// The fitted map's net of element `e` (the search's copy where it made one).
    fn fitted_net(&self, e: usize) -> Net {
        match self.references.0[e].get() {
            Some(r) => r.2,
            None => self.fitted.bezier_net(e),
        }
    }

    /// Blended net of element `e` under `factors`.
    fn net_with(&self, e: usize, factors: &[f32], reduced: bool) -> Net {
        if !reduced || factors.is_empty() {
            return self.fitted.bezier_net(e);
        }
        let (s, t, f) = &**self.references.0[e].get_or_init(|| {
            Box::new((
                self.straight.bezier_net(e),
                self.target.bezier_net(e),
                self.fitted.bezier_net(e),
            ))
        });
        let ids = self.ids.of(e);
        let mut out = *f;
        for i in 0..self.points() {
            let x = factors[ids[i] as usize] as f64;
            if x >= 2.0 {
                continue;
            }
            out[i] = if x >= 1.0 {
                std::array::from_fn(|k| t[i][k] + (x - 1.0) * (f[i][k] - t[i][k]))
            } else {
                std::array::from_fn(|k| s[i][k] + x * (t[i][k] - s[i][k]))
            };
        }
        out
    }
}

impl BezierElements for Blended<'_> {
    fn dim(&self) -> usize {
        self.fitted.dim()
    }
    fn n_elements(&self) -> usize {
        self.fitted.n_elements()
    }
    fn bezier_net(&self, e: usize) -> Net {
        self.net_with(e, &self.factors, self.is_reduced(e))
    }
}

/// The straight elements' certified lower bounds of det J and their Jacobian ratios (from
/// their corners), for the elements `mine` (the other entries are 0 and NaN); the invalid
/// ones of every share are an error on every share.
fn straight_reference(
    certifier: &dyn Certifier,
    blended: &Blended,
    depth: usize,
    mine: &[usize],
    share: &dyn BlendShare,
) -> Result<(Vec<f64>, Vec<f64>), BlendError> {
    let n = blended.n_elements();
    let dim = blended.dim();
    let net = |e: usize| blended.straight.bezier_net(e);
    let bounds = certify_screened(certifier, dim, mine, &net, depth, &|_| 0.0).bounds;
    let bad: Vec<usize> = mine
        .iter()
        .zip(&bounds)
        .filter(|(_, b)| !(b.lower > 0.0))
        .map(|(&e, _)| e)
        .collect();
    let n_bad = share.sum(bad.len());
    let (bad, any_bad) = share.union(bad);
    if any_bad {
        return Err(BlendError::StraightInvalid {
            count: n_bad,
            first: bad.into_iter().take(8).collect(),
        });
    }
    let mesh = blended.geometry;
    let shapes: Vec<f64> = mine.par_iter().map(|&e| corner_ratio(mesh, e)).collect();
    let mut lower = vec![0.0; n];
    let mut ratio = vec![f64::NAN; n];
    for ((&e, b), s) in mine.iter().zip(&bounds).zip(shapes) {
        lower[e] = b.lower;
        ratio[e] = s;
    }
    Ok((lower, ratio))
}

/// How [`blend_search_shared`] shares the search with other processes that judge the other
/// elements (the distributed job): each judges its own elements, and they agree on the
/// rejected elements of every round, from which each applies the same factor reductions to
/// its copy of the factors, so the factors are those of the search over the whole mesh.
pub trait BlendShare {
    /// The elements this process judges (`None`: all).
    fn mine(&self) -> Option<&[usize]>;
    /// The union of every process's `elements`: the members this process holds, in the
    /// whole mesh's order ([`BlendShare::global`]; the reduction of a round depends on it), and
    /// whether the union is non-empty anywhere (every process gets the same flag, so loops
    /// and early returns on it stay collective).
    fn union(&self, elements: Vec<usize>) -> (Vec<usize>, bool);
    /// Every process's `values`, concatenated.
    fn concat(&self, values: Vec<f64>) -> Vec<f64>;
    /// The sum of every process's `v`.
    fn sum(&self, v: usize) -> usize;
    /// The minimum of every process's `v`.
    fn min(&self, v: f64) -> f64;
    /// The whole mesh's index of this process's element `e`.
    fn global(&self, e: usize) -> usize;
}

/// The whole search in this process.
pub struct Alone;

impl BlendShare for Alone {
    fn mine(&self) -> Option<&[usize]> {
        None
    }
    fn union(&self, elements: Vec<usize>) -> (Vec<usize>, bool) {
        let any = !elements.is_empty();
        (elements, any)
    }
    fn concat(&self, values: Vec<f64>) -> Vec<f64> {
        values
    }
    fn sum(&self, v: usize) -> usize {
        v
    }
    fn min(&self, v: f64) -> f64 {
        v
    }
    fn global(&self, e: usize) -> usize {
        e
    }
}

/// The next factor of a rejected entity: twice halve the way to 1 (the fitted map's C¹ shape
/// is what the target map lacks, so a little of it is worth trying before giving it up), then
/// 1, then halve the way to 0 at most `max_bisections` times, then 0.
fn reduce(x: f32, max_bisections: usize) -> f32 {
    let tiny = 0.5f32.powi(max_bisections as i32);
    if x > 1.0 {
        if x > 1.25 { 1.0 + 0.5 * (x - 1.0) } else { 1.0 }
    } else if x > tiny {
        0.5 * x
    } else {
        0.0
    }
}

/// Find the factors (see the module docs) and store them in `blended`.
pub fn blend_search(
    certifier: &dyn Certifier,
    blended: &mut Blended,
    params: &BlendParams,
) -> Result<BlendInfo, BlendError> {
    blend_search_shared(certifier, blended, params, &Alone)
}

/// What [`blend_search_at_most`] finds.
#[derive(Debug)]
pub enum Bounded {
    /// The search ran to its end: the factors and figures of [`blend_search`].
    Done(BlendInfo),
    /// The search stopped once more elements than the bound were held back; at least this
    /// many are held back at its end (a held-back point is never raised again). The factors
    /// are not certified and nothing is stored in the blend.
    Exceeded(usize),
}

/// [`blend_search`], given up as soon as more than `max_reduced` elements are held back
/// (local mode: each round can only add held-back elements, so the count so far is a lower
/// bound of the final one). For a caller that only needs the result when few elements are
/// held back; the rounds after the bound is passed are not run.
pub fn blend_search_at_most(
    certifier: &dyn Certifier,
    blended: &mut Blended,
    params: &BlendParams,
    max_reduced: usize,
) -> Result<Bounded, BlendError> {
    search(certifier, blended, params, &Alone, Some(max_reduced))
}

/// [`blend_search_at_most`] sharing the judging with other processes ([`BlendShare`]): given
/// up once more than `max_reduced` elements of all processes are held back, on every process
/// at the same round.
pub fn blend_search_shared_at_most(
    certifier: &dyn Certifier,
    blended: &mut Blended,
    params: &BlendParams,
    share: &dyn BlendShare,
    max_reduced: usize,
) -> Result<Bounded, BlendError> {
    search(certifier, blended, params, share, Some(max_reduced))
}

/// [`blend_search`] sharing the judging of the elements with other processes ([`BlendShare`]).
/// The factors and the info are those of [`blend_search`] on the whole mesh (`worst` names
/// the elements by their whole mesh's index, [`BlendShare::global`]).
pub fn blend_search_shared(
    certifier: &dyn Certifier,
    blended: &mut Blended,
    params: &BlendParams,
    share: &dyn BlendShare,
) -> Result<BlendInfo, BlendError> {
    match search(certifier, blended, params, share, None)? {
        Bounded::Done(info) => Ok(info),
        Bounded::Exceeded(_) => unreachable!("an unbounded search runs to its end"),
    }
}

/// The search of [`blend_search_shared`], given up once more than `max_reduced` elements
/// (of all processes) are held back, when given.
fn search(
    certifier: &dyn Certifier,
    blended: &mut Blended,
    params: &BlendParams,
    share: &dyn BlendShare,
    max_reduced: Option<usize>,
) -> Result<Bounded, BlendError> {
    let (n, dim, np) = (blended.n_elements(), blended.dim(), blended.points());
    let depth = params.certificate_depth;
    let all: Vec<usize> = (0..n).collect();
    let mine: &[usize] = share.mine().unwrap_or(&all);
    let mut owned = vec![share.mine().is_none(); n];
    mine.iter().for_each(|&e| owned[e] = true);
    let (straight_lower, straight_ratio) =
        straight_reference(certifier, blended, depth, mine, share)?;
    // Every process's ratios: the minimum and percentile are the whole mesh's.
    let mut sorted = share.concat(mine.iter().map(|&e| straight_ratio[e]).collect());
    sorted.sort_by(f64::total_cmp);
    let p1 = sorted.get(sorted.len() / 100).copied().unwrap_or(1.0);
    // The same for the straight elements' scaled Jacobians.
    // Without the floor, its target is the element rule's (q_min · s_S): phase 2 finds
    // nothing below it.
    let fractions = (
        params.min_quality_fraction,
        if params.scaled_jacobian_floor {
            params.percentile_quality_fraction
        } else {
            0.0
        },
    );
    let sj =
        StraightScaledJacobians::new(blended.straight, mine, &straight_lower, fractions, share);
    let det_target = |e: usize| params.min_det_fraction.max(0.0) * straight_lower[e];
    let quality = params.min_quality_fraction > 0.0 || params.percentile_quality_fraction > 0.0;
    let ratio_target = |e: usize| {
        let r = straight_ratio[e];
        (params.min_quality_fraction * r).max(params.percentile_quality_fraction * r.min(p1))
    };
    // Judged: det J above its target, then (only then, since it costs the det J polynomial)
    // the ratio bound, then the scaled Jacobian against its two targets.
    let accept = |e: usize, b: &DetBounds, net: &Net, kept: f64| -> Judged {
        let judged = |accepted: bool, floor: bool, lower: f64| Judged {
            valid: true,
            accepted,
            floor: accepted && floor,
            lower,
        };
        if !(b.lower > det_target(e)) {
            return Judged {
                valid: false,
                accepted: false,
                floor: false,
                lower: b.lower,
            };
        }
        if !quality {
            return judged(true, true, b.lower);
        }
        let hadamard = hadamard_upper(dim, net);
        let shape = || sj.verdict(e, net, b.lower / hadamard, kept);
        // Cheap first: the screened lower bound against the Hadamard upper bound of max det J.
        if b.lower >= ratio_target(e) * hadamard {
            let (own, floor) = shape();
            return judged(own, floor, b.lower);
        }
        // The coefficients' min over max is pessimistic on a curved element (while the
        // straight ratio is exact): refine both bounds by subdivision until decided.
        let poly = det_jacobian_bernstein(dim, net);
        let (ok, lower) = certify_ratio(dim, poly, ratio_target(e), depth);
        let (own, floor) = if ok { shape() } else { (false, false) };
        judged(ok && own, floor, lower.max(b.lower))
    };
    // `elements` sorted. The blended nets are built once per call (a reduced element's costs
    // the target map's smooth corrections, any other's the spline's evaluation) and shared by
    // the screen, the certificate and the quality test, a chunk of elements at a time so that
    // the full-fit call does not hold every element's net at once.
    let judge =
        |blended: &Blended, factors: &[f32], reduced: &[bool], elements: &[usize], kept: &[f64]| {
            let blend =
                |e: usize| blended.net_with(e, factors, reduced.get(e).copied().unwrap_or(false));
            let mut verdicts = Vec::with_capacity(elements.len());
            for chunk in elements.chunks(JUDGE_CHUNK) {
                let nets: Vec<Net> = chunk.par_iter().map(|&e| blend(e)).collect();
                let net = |e: usize| match chunk.binary_search(&e) {
                    Ok(i) => nets[i],
                    _ => blend(e),
                };
                let cert = certify_screened(certifier, dim, chunk, &net, depth, &det_target);
                verdicts.par_extend(chunk.par_iter().zip(&nets).zip(&cert.bounds).map(
                    |((&e, n), b)| {
                        accept(e, b, n, kept.get(e).copied().unwrap_or(f64::NEG_INFINITY))
                    },
                ));
            }
            verdicts
        };
    let first = judge(blended, &[], &[], mine, &[]);
    let mut info = BlendInfo {
        invalid_at_full_step: share.sum(first.iter().filter(|r| !r.valid).count()),
        poor_at_full_step: share.sum(first.iter().filter(|r| r.valid && !r.floor).count()),
        straight_ratio_min: sorted.first().copied().unwrap_or(1.0),
        straight_ratio_p1: p1,
        min_factor: FITTED as f64,
        ..Default::default()
    };
    // Lower bounds of this process's elements (+∞ elsewhere, for the minimum).
    let mut lower = vec![f64::INFINITY; n];
    // Whether this process's elements met the floor when last judged (an element is judged
    // again whenever a point of it changes).
    let mut floor = vec![true; n];
    for (&e, r) in mine.iter().zip(&first) {
        lower[e] = r.lower;
        floor[e] = r.floor;
    }
    let (mut bad, mut any_bad) = share.union(
        mine.iter()
            .zip(&first)
            .filter(|(_, r)| !r.accepted)
            .map(|(&e, _)| e)
            .collect(),
    );
    let mut factors = Vec::new();
    if any_bad {
        factors = vec![FITTED; blended.ids.len()];
    }
    let mut reduced = vec![false; if any_bad { n } else { 0 }];
    if params.global && any_bad {
        let r = global_bisection(
            &judge,
            blended,
            &mut factors,
            params,
            mine,
            share,
            &mut info,
        );
        for (&e, r) in mine.iter().zip(&r) {
            lower[e] = r.lower;
        }
        reduced.fill(true);
        bad.clear();
        any_bad = false;
    }
    // Phase 1, the element rules; phase 2 (`floored`), the scaled Jacobian's floor too,
    // from where phase 1 ended (factors only go down, so phase 1's held-back elements stay).
    let mut floored = params.global;
    let mut before_floor = None;
    // Phase 2's second target of this process's elements besides the floor (−∞ until set):
    // min(the element's scaled Jacobian where phase 1 ended, `lowest`), recorded before the
    // element's first change in phase 2, `lowest` the smallest of those values around the
    // elements the floor rejects first. Holding an element back to its floor then pushes no
    // neighbour below where phase 1 left it, unless that is above `lowest`; and `lowest` is
    // at least phase 1's smallest scaled Jacobian, which the mesh therefore keeps.
    let mut kept: Vec<f64> = Vec::new();
    let mut lowest = f64::INFINITY;
    // The scaled Jacobians at the current factors of the elements of `elements` whose
    // second target is not set (this process's).
    let unset = |kept: &[f64], factors: &[f32], reduced: &[bool], elements: &[usize]| {
        let unset: Vec<usize> = elements
            .iter()
            .copied()
            .filter(|&e| owned[e] && kept[e] == f64::NEG_INFINITY)
            .collect();
        let values: Vec<f64> = unset
            .par_iter()
            .map(|&e| fine_lattice_scaled_jacobian(dim, &blended.net_with(e, factors, reduced[e])))
            .collect();
        unset.into_iter().zip(values).collect::<Vec<_>>()
    };
    loop {
        // Until no process has a rejected element: a process whose own elements are all
        // accepted still takes part in every round's exchange.
        while any_bad {
            let mut recheck = around(blended, &bad);
            if !kept.is_empty() {
                // Every point lowered now is on an element of `recheck`: those not changed yet
                // in phase 2 are at phase 1's factors.
                let first = unset(&kept, &factors, &reduced, &recheck);
                if lowest == f64::INFINITY {
                    let here = first.iter().map(|v| v.1).fold(f64::INFINITY, f64::min);
                    lowest = share.min(here);
                }
                for (e, v) in first {
                    kept[e] = v.min(lowest);
                }
            }
            reduce_rejected(blended, &mut factors, &bad, params.max_bisections);
            for &e in &recheck {
                reduced[e] = blended.ids.of(e)[..np]
                    .iter()
                    .any(|&id| factors[id as usize] < FITTED);
            }
            if let Some(max) = max_reduced.filter(|_| !floored) {
                // Factors only go down, so an element held back now stays held back.
                let held = share.sum(mine.iter().filter(|&&e| reduced[e]).count());
                if held > max {
                    return Ok(Bounded::Exceeded(held));
                }
            }
            recheck.retain(|&e| owned[e]);
            let r = judge(blended, &factors, &reduced, &recheck, &kept);
            info.rounds += 1;
            let mut mine_bad = Vec::new();
            for (&e, r) in recheck.iter().zip(&r) {
                lower[e] = r.lower;
                floor[e] = r.floor;
                // A straight element is accepted by construction (its own reference).
                let accepted = if floored { r.floor } else { r.accepted };
                if !accepted && !is_straight(blended, &factors, e) {
                    mine_bad.push(e);
                }
            }
            (bad, any_bad) = share.union(mine_bad);
        }
        if floored {
            break;
        }
        floored = true;
        // `reduced` is empty where phase 1 rejected nothing.
        let held = mine
            .iter()
            .filter(|&&e| reduced.get(e).copied().unwrap_or(false));
        before_floor = Some(share.sum(held.count()));
        let below: Vec<usize> = mine
            .iter()
            .copied()
            .filter(|&e| !floor[e] && (factors.is_empty() || !is_straight(blended, &factors, e)))
            .collect();
        (bad, any_bad) = share.union(below);
        if any_bad && factors.is_empty() {
            factors = vec![FITTED; blended.ids.len()];
            reduced = vec![false; n];
        }
        if any_bad {
            kept = vec![f64::NEG_INFINITY; n];
        }
    }
    blended.factors = factors;
    blended.refresh();
    summarise(blended, &mut info, &lower, &owned, share);
    info.reduced_before_floor = before_floor.unwrap_or(info.reduced_elements);
    info.worst = worst_over(share, &info.worst);
    info.reduced_elements = share.sum(info.reduced_elements);
    info.min_det_lower_bound = share.min(info.min_det_lower_bound);
    info.min_factor = share.min(info.min_factor);
    Ok(Bounded::Done(info))
}

/// Reduced elements listed in [`BlendInfo::worst`].
const WORST: usize = 10;

/// The [`WORST`] elements of every process's `own` list (the largest withheld displacement
/// first, then the lowest element), in the whole mesh's element indices: the list of the
/// search over the whole mesh.
fn worst_over(share: &dyn BlendShare, own: &[ReducedElement]) -> Vec<ReducedElement> {
    let flat = own
        .iter()
        .flat_map(|r| {
            let [x, y, z] = r.centroid;
            let e = share.global(r.element) as f64;
            [e, x, y, z, r.min_factor, r.withheld]
        })
        .collect();
    let mut all: Vec<ReducedElement> = share
        .concat(flat)
        .chunks_exact(6)
        .map(|c| ReducedElement {
            element: c[0] as usize,
            centroid: [c[1], c[2], c[3]],
            min_factor: c[4],
            withheld: c[5],
        })
        .collect();
    all.sort_by(|a, b| (b.withheld.total_cmp(&a.withheld)).then(a.element.cmp(&b.element)));
    all.truncate(WORST);
    all
}

/// What the search learns of an element.
#[derive(Clone, Copy, Debug)]
struct Judged {
    /// det J certified above its target.
    valid: bool,
    /// Accepted by the element rules (phase 1 of the search): valid, the Jacobian ratio's
    /// rule, and the scaled Jacobian at least q_min × the straight element's.
    accepted: bool,
    /// Accepted and its scaled Jacobian at least the floor max(q_min · s_S, q_p · min(s_S, P_s))
    /// too (phase 2).
    floor: bool,
    /// Certified lower bound of det J.
    lower: f64,
}

/// Whether every point of element `e` is at the straight elevation (factor 0).
fn is_straight(blended: &Blended, factors: &[f32], e: usize) -> bool {
    blended.ids.of(e)[..blended.points()]
        .iter()
        .all(|&id| factors[id as usize] == 0.0)
}

/// The search's judge: the verdicts on `elements` of the blend with `factors`, `reduced`
/// marking the elements with a point below the fitted map, and the floor at least `kept`
/// (per element; −∞ where it is empty).
type Judge<'j> = dyn Fn(&Blended, &[f32], &[bool], &[usize], &[f64]) -> Vec<Judged> + 'j;

/// Global mode: bisection on one factor in [0, 2] for the whole mesh (0, the straight
/// elevation, is accepted). Leaves the factor found in `factors` and returns the verdicts on
/// `mine` there.
fn global_bisection(
    judge: &Judge,
    blended: &Blended,
    factors: &mut [f32],
    params: &BlendParams,
    mine: &[usize],
    share: &dyn BlendShare,
    info: &mut BlendInfo,
) -> Vec<Judged> {
    let reduced = vec![true; blended.n_elements()];
    let (mut lo, mut hi) = (0.0f32, FITTED);
    for _ in 0..2 * params.max_bisections.max(1) {
        let mid = 0.5 * (lo + hi);
        factors.fill(mid);
        let r = judge(blended, factors, &reduced, mine, &[]);
        info.rounds += 1;
        if share.sum(r.iter().filter(|r| !r.floor).count()) == 0 {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    factors.fill(lo);
    judge(blended, factors, &reduced, mine, &[])
}

/// One round's reduction: the factors of the rejected elements `bad` lowered ([`reduce`]).
fn reduce_rejected(blended: &Blended, factors: &mut [f32], bad: &[usize], max_bisections: usize) {
    let np = blended.points();
    let mut touched = vec![false; factors.len()];
    for &e in bad {
        // Down to the target map first: a mix of fitted and target points can fail where
        // neither map does, and giving up the target map's curvature is the last resort.
        let ids = blended.ids.of(e);
        let above = ids[..np].iter().any(|&id| factors[id as usize] > 1.0);
        for &id in &ids[..np] {
            let id = id as usize;
            if !touched[id] && (!above || factors[id] > 1.0) {
                touched[id] = true;
                factors[id] = reduce(factors[id], max_bisections);
            }
        }
    }
}

/// The elements to judge again after [`reduce_rejected`] of `bad` (sorted): those sharing a
/// point it may change, which contain one of the rejected elements' vertices.
fn around(blended: &Blended, bad: &[usize]) -> Vec<usize> {
    let mut recheck: Vec<usize> = bad
        .iter()
        .flat_map(|&e| blended.ids.mesh.element(e).to_vec())
        .flat_map(|v| blended.ids.topo.elements_at_vertex(v as usize).to_vec())
        .map(|e| e as usize)
        .collect();
    recheck.sort_unstable();
    recheck.dedup();
    recheck
}

/// Fill the reduction counts and the worst reduced elements of `info`.
/// Only the elements marked `owned` are listed and counted; a point is counted by the
/// process owning the lowest element (in the whole mesh's indices) around it, and the
/// point counts are summed over the processes.
fn summarise(
    blended: &Blended,
    info: &mut BlendInfo,
    lower: &[f64],
    owned: &[bool],
    share: &dyn BlendShare,
) {
    let n = blended.n_elements();
    let dim = blended.dim();
    let np = blended.points();
    info.min_det_lower_bound = lower.iter().copied().fold(f64::INFINITY, f64::min);
    let mesh = blended.geometry;
    let per: Vec<Option<ReducedElement>> = (0..n)
        .into_par_iter()
        .map(|e| {
            if !owned[e] || !blended.is_reduced(e) {
                return None;
            }
            let (b, f) = (blended.bezier_net(e), blended.fitted_net(e));
            let ids = blended.ids.of(e);
            let x = mesh.element_coords(e);
            let nc = 1 << dim;
            let mut h = f64::INFINITY;
            for a in 0..nc {
                for c in a + 1..nc {
                    h = h.min((DVec3::from(x[a]) - DVec3::from(x[c])).length());
                }
            }
            let (mut min_factor, mut withheld) = (FITTED as f64, 0.0f64);
            for i in 0..np {
                let l = blended.factors[ids[i] as usize] as f64;
                min_factor = min_factor.min(l);
                withheld = withheld.max((DVec3::from(f[i]) - DVec3::from(b[i])).length());
            }
            let centroid =
                std::array::from_fn(|k| x[..nc].iter().map(|p| p[k]).sum::<f64>() / nc as f64);
            Some(ReducedElement {
                element: e,
                centroid,
                min_factor,
                withheld: withheld / h.max(f64::MIN_POSITIVE),
            })
        })
        .collect();
    let mut reduced: Vec<ReducedElement> = per.into_iter().flatten().collect();
    info.reduced_elements = reduced.len();
    // Per point shared with other processes: the lowest element around it here and whether
    // it is owned (every element around a point of an own element is held here, so that is
    // the whole mesh's lowest). Empty: every point is this process's, or no factor was
    // lowered on this process (`factors` is empty, nothing to count).
    let mut lowest = Vec::new();
    if share.mine().is_some() && !blended.factors.is_empty() {
        lowest = vec![(usize::MAX, false); blended.factors.len()];
        for e in 0..n {
            let g = share.global(e);
            for &id in &blended.ids.of(e)[..np] {
                let l = &mut lowest[id as usize];
                if g < l.0 {
                    *l = (g, owned[e]);
                }
            }
        }
    }
    let counted = |keep: fn(f32) -> bool| {
        let ours = |i: usize| lowest.get(i).is_none_or(|l| l.1);
        let here = blended.factors.iter().enumerate();
        share.sum(here.filter(|&(i, &l)| keep(l) && ours(i)).count())
    };
    info.reduced_points = counted(|l| l < FITTED);
    info.target_points = counted(|l| l <= 1.0);
    info.straight_points = counted(|l| l == 0.0);
    info.min_factor = reduced
        .iter()
        .map(|r| r.min_factor)
        .fold(FITTED as f64, f64::min);
    reduced.sort_by(|a, b| b.withheld.total_cmp(&a.withheld));
    reduced.truncate(WORST);
    info.worst = reduced;
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The quadratic tensor Bézier map of `net` at `xi` (index 9z + 3y + x).
    fn eval(dim: usize, net: &Net, xi: [f64; 3]) -> [f64; 3] {
        let b = |t: f64| [(1.0 - t) * (1.0 - t), 2.0 * t * (1.0 - t), t * t];
        let (bx, by, bz) = (b(xi[0]), b(xi[1]), b(xi[2]));
        let mut x = [0.0; 3];
        for i in 0..net_len(dim) {
            let w = bx[i % 3] * by[(i / 3) % 3] * if dim == 2 { 1.0 } else { bz[i / 9] };
            for k in 0..3 {
                x[k] += w * net[i][k];
            }
        }
        x
    }

    /// The lattice scaled Jacobians ({0, ½, 1}^d and {0, ¼, ½, ¾, 1}^d) against central
    /// differences of the map itself, on perturbed nets in 2D and 3D (mildly and strongly
    /// distorted).
    #[test]
    fn lattice_scaled_jacobian_matches_differences_of_the_map() {
        let mut seed = 7u64;
        let mut rand = || {
            seed = seed
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (seed >> 11) as f64 / (1u64 << 53) as f64 - 0.5
        };
        for (dim, amp) in [(2, 0.3), (3, 0.3), (2, 1.5), (3, 1.5)] {
            let mut net = [[0.0; 3]; 27];
            for (i, p) in net.iter_mut().enumerate().take(net_len(dim)) {
                let l = [i % 3, (i / 3) % 3, i / 9];
                for k in 0..dim {
                    p[k] = [1.0, 2.0, 0.5][k] * l[k] as f64 / 2.0 + amp * 0.5 * rand();
                }
            }
            for (m, lattice) in [
                (3, lattice_scaled_jacobian as fn(usize, &Net) -> f64),
                (5, fine_lattice_scaled_jacobian),
            ] {
                let h = 1e-6;
                let mut expected = f64::INFINITY;
                for p in 0..if dim == 2 { m * m } else { m * m * m } {
                    let xi = [p % m, (p / m) % m, p / (m * m)].map(|l| l as f64 / (m - 1) as f64);
                    let col = |k: usize| -> [f64; 3] {
                        let (mut a, mut b) = (xi, xi);
                        a[k] += h;
                        b[k] -= h;
                        let (xa, xb) = (eval(dim, &net, a), eval(dim, &net, b));
                        std::array::from_fn(|q| (xa[q] - xb[q]) / (2.0 * h))
                    };
                    let (c0, c1, c2) = (col(0), col(1), col(2));
                    let sj = if dim == 2 {
                        (c0[0] * c1[1] - c0[1] * c1[0])
                            / (DVec3::from(c0).length() * DVec3::from(c1).length())
                    } else {
                        let [c0, c1, c2] = [c0, c1, c2].map(DVec3::from);
                        c0.cross(c1).dot(c2) / (c0.length() * c1.length() * c2.length())
                    };
                    expected = expected.min(sj);
                }
                let got = lattice(dim, &net);
                assert!(
                    (got - expected).abs() < 1e-6,
                    "dim {dim}, {m} points an axis: {got} vs {expected}"
                );
            }
        }
    }
}
