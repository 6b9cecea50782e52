//! Post-fit Q2 choice: spline elements whose boundary side the least-squares fit leaves far
//! from its smooth targets.
//!
//! Input: the mesh, its topology, the spline space, the fitted control points and the smooth
//! targets. Output: a mark per element, set on spline elements to make constrained Q2 elements
//! before the fit is repeated (the pipeline does this for a few rounds).
//!
//! A C¹ spline cannot bend a short run of boundary sides between Q2 elements (or next to an
//! irregular stretch of the boundary grid) onto the surface: the run's side midpoints stay off
//! their targets by many times what a Q2 element, which interpolates its targets, would leave
//! between its nodes. Per boundary side of every element the check measures
//! * d, the largest distance of the fitted map from the targets at the side's lattice points
//!   {0, ½, 1}^(d−1) (a Q2 side whose nodes are its own has d ≈ 0);
//! * e_Q, an estimate of a Q2 side's own error between its nodes: s³ / ℓ², with s the largest
//!   target correction of the side (its sagitta) and ℓ its edge length. On a circle of
//!   curvature κ, s = ℓ²κ / 8 and the interpolation error of the quadratic through three
//!   points is about ℓ⁴κ³ / 500, which is s³ / ℓ² (Gmsh's order-2 sides on the CAD measure
//!   this within 10 %).
//!
//! A boundary side of a spline element is *over* when d > `MISFIT_FACTOR` · e_Q +
//! `MISFIT_FLOOR` · ℓ. An over side is a *seed* when also d > `NEIGHBOUR_FACTOR` times the
//! smallest d of the boundary sides sharing a vertex with it, and the elements of the seeds
//! and of every over side connected to a seed through over sides (sharing vertices) are
//! marked. The neighbour rule keeps a boundary whose spline sides all fit alike (an O-grid
//! ring, uniformly a few e_Q off) as it is: only runs that start next to a much better side are
//! the spline space's local failures, and each is marked whole. A run of more than `MAX_RUN`
//! sides is not marked: along a structured wall (a whole airfoil, cylinder or turbine blade)
//! every spline side can be over the threshold by the spline's ordinary error constant, next
//! to one Q2 element, and such a wall stays C¹. Straight stretches (s = 0) are marked only
//! above the floor, far below any visible deviation.
//!
//! The marking is a function of the sides' figures alone ([`SideFigures`], vertices by key),
//! so the distributed run gathers its ranks' sides and marks the same runs.

use crate::fit::SmoothTargets;
use crate::math::bernstein::net_len;
use crate::math::bernstein::{BezierElements, eval_net_with_derivatives};
use crate::math::linalg::DVec3;
use crate::math::reference::HEX_VERTEX_PARAMS;
use crate::mesh::topology::NONE;
use crate::mesh::{LinearMesh, Topology};
use crate::spline::SplineSpace;
use crate::spline::eval::eval_net;
use rayon::prelude::*;
use std::collections::HashMap;

/// A boundary side is a misfit above this many times the Q2 error estimate s³ / ℓ².
pub(crate) const MISFIT_FACTOR: f64 = 2.0;

/// ... and above this many times the smallest deviation of a boundary side sharing a vertex.
pub(crate) const NEIGHBOUR_FACTOR: f64 = 3.0;

/// Deviations below this fraction of the side's edge length are never misfits.
pub(crate) const MISFIT_FLOOR: f64 = 1e-8;

/// Runs of more boundary sides than this are left to the spline: a long run over its
/// threshold is the spline space's ordinary error along a structured wall (a whole airfoil or
/// cylinder wall is such a run), not a local failure between Q2 elements, and making it Q2
/// would trade the wall's C¹ continuity for little. The runs of the plate with a hole reach
/// 23 sides at level 3.
pub(crate) const MAX_RUN: usize = 32;

/// Fit-and-demote rounds after the first fit.
pub(crate) const MISFIT_ROUNDS: usize = 3;

/// One boundary side: its element, facet, deviation d and threshold from e_Q and the floor.
pub(crate) struct Side {
    pub element: u32,
    pub facet: u32,
    pub deviation: f64,
    pub threshold: f64,
}

/// The lattice index (9z + 3y + x) of lattice point `l`.
fn index(l: [usize; 3]) -> usize {
    l[0] + 3 * l[1] + 9 * l[2]
}

/// The boundary sides of element `e` with their deviations from the targets.
fn element_sides(
    mesh: &LinearMesh,
    topo: &Topology,
    space: &SplineSpace,
    control_points: &[[f64; 3]],
    targets: &SmoothTargets,
    e: usize,
    out: &mut Vec<Side>,
) {
    let dim = topo.dim;
    let boundary: Vec<usize> = (0..2 * dim)
        .filter(|&s| topo.facet_elements[topo.element_facet(e, s) as usize][1] == NONE)
        .collect();
    if boundary.is_empty() {
        return;
    }
    let x = mesh.element_coords(e);
    let corrections = targets.element_corrections(mesh, topo, e);
    let net = space.element_bezier_with(e, control_points);
    // The multilinear point of lattice point l: the average of the corners of the smallest
    // entity containing it.
    let multilinear = |l: [usize; 3]| {
        let mut p = DVec3::ZERO;
        let mut n = 0.0;
        for (c, pc) in HEX_VERTEX_PARAMS.iter().enumerate().take(1 << dim) {
            if (0..dim).all(|k| l[k] == 1 || 2 * pc[k] as usize == l[k]) {
                p += DVec3::from(x[c]);
                n += 1.0;
            }
        }
        p / n
    };
    for s in boundary {
        let (k, b) = (s / 2, 2 * (s % 2));
        let (mut deviation, mut sagitta, mut length) = (0.0f64, 0.0f64, 0.0f64);
        let n = if dim == 2 { 3 } else { 9 };
        let others: Vec<usize> = (0..dim).filter(|&j| j != k).collect();
        for i in 0..n {
            let mut l = [0usize; 3];
            l[k] = b;
            l[others[0]] = i % 3;
            if dim == 3 {
                l[others[1]] = i / 3;
            }
            let c = DVec3::from(corrections[index(l)]);
            let target = multilinear(l) + c;
            let u = [l[0] as f64 / 2.0, l[1] as f64 / 2.0, l[2] as f64 / 2.0];
            let fitted = DVec3::from(eval_net(dim, &net, u));
            deviation = deviation.max((fitted - target).length());
            sagitta = sagitta.max(c.length());
            // Edge lengths: a corner and the next corner along each other direction.
            for &j in &others {
                if l[j] == 0 && l.iter().enumerate().all(|(m, &v)| m == k || v != 1) {
                    let mut q = l;
                    q[j] = 2;
                    length = length.max((multilinear(q) - multilinear(l)).length());
                }
            }
        }
        let eq = if length > 0.0 {
            sagitta.powi(3) / (length * length)
        } else {
            0.0
        };
        out.push(Side {
            element: e as u32,
            facet: topo.element_facet(e, s),
            deviation,
            threshold: MISFIT_FACTOR * eq + MISFIT_FLOOR * length,
        });
    }
}

/// Marks of the spline elements whose boundary side the fit leaves far off its targets (see
/// the module docs); `control_points` are the fitted ones.
pub(crate) fn misfit_elements(
    mesh: &LinearMesh,
    topo: &Topology,
    space: &SplineSpace,
    control_points: &[[f64; 3]],
    targets: &SmoothTargets,
) -> Vec<bool> {
    let all = vec![true; topo.n_elements];
    let sides = boundary_sides(mesh, topo, space, control_points, targets, &all);
    let figures: Vec<SideFigures> = sides
        .iter()
        .map(|side| side.figures(topo, space, u64::from))
        .collect();
    let mut marks = vec![false; topo.n_elements];
    for (side, marked) in sides.iter().zip(marked_sides(&figures)) {
        marks[side.element as usize] |= marked;
    }
    marks
}

/// The boundary sides of the elements in `which` (indexed by element), with their deviations.
pub(crate) fn boundary_sides(
    mesh: &LinearMesh,
    topo: &Topology,
    space: &SplineSpace,
    control_points: &[[f64; 3]],
    targets: &SmoothTargets,
    which: &[bool],
) -> Vec<Side> {
    let ne = topo.n_elements;
    let mut on_boundary = vec![false; ne];
    for &f in &topo.boundary_facets {
        let e = topo.facet_elements[f as usize][0] as usize;
        on_boundary[e] = which[e];
    }
    (0..ne)
        .into_par_iter()
        .filter(|&e| on_boundary[e])
        .flat_map_iter(|e| {
            let mut out = Vec::new();
            element_sides(mesh, topo, space, control_points, targets, e, &mut out);
            out
        })
        .collect()
}

/// Parameters per direction at which [`boundary_sq_sum`] measures a boundary side.
const SIDE_SAMPLES: usize = 5;

/// The samples [`boundary_sq_sum`] takes on one boundary side of a `dim`-dimensional mesh.
fn samples_per_side(dim: usize) -> usize {
    SIDE_SAMPLES.pow(dim as u32 - 1)
}

/// Squared distances of `map`'s boundary from `surface`'s (both over the elements of `topo`),
/// summed over the boundary sides of the elements `e` with `which(e)`, and their count: for
/// every such side, the points of `map` at 5 × 5 (2D: 5) parameters inside the side (the
/// centres of a 5 × 5 grid of it), each at its distance from the same side of `surface`, found
/// by Gauss–Newton from the same parameters. [`rms`] of the sums is the RMS distance; the sums
/// of a distributed job's ranks, each over its own elements, add up to the whole mesh's.
///
/// The distance is to the nearest point, not to the point of the same parameters: two maps of
/// one boundary may slide along it against each other (a spline's parametrisation of a graded
/// wall does), and only the distance across it is an error of the shape. Sides whose element
/// has the same net in both maps (an element the blend does not hold back, against its own
/// fit) are counted at distance 0 without projecting.
pub(crate) fn boundary_sq_sum(
    topo: &Topology,
    map: &dyn BezierElements,
    surface: &dyn BezierElements,
    which: &(dyn Fn(usize) -> bool + Sync),
) -> (f64, usize) {
    boundary_sq_sum_reaching(topo, map, surface, which, 0.0)
}

/// How far beyond its side (a share of the side's parameter range) [`boundary_sq_sum_reaching`]
/// seeks the nearest point on the side's patch extended, where a redo may reparametrise the
/// boundary: the interior kinks' redo (`pipeline::passes`) makes elements Q2 whose boundary
/// sides are their targets while the pass kept's spline slid the same sides along the
/// boundary. On the generated 1,536-hex cylinder the fit moves the caps' points within the
/// cap by up to 0.29 of the shortest edge at the butterfly's turns: measured within the side
/// the redo moved the boundary by 1.0e-5 of the diagonal, while its nodes stay as close to the
/// exact cylinder as the pass kept's (RMS 5.9e-6 against 5.8e-6).
pub(crate) const SLIDE_REACH: f64 = 0.5;

/// [`boundary_sq_sum`] with the nearest point sought on the same side of `surface` extended by
/// `reach` of its parameter range on every side (0: within the side): slides along the
/// boundary up to that far are not counted as distance.
pub(crate) fn boundary_sq_sum_reaching(
    topo: &Topology,
    map: &dyn BezierElements,
    surface: &dyn BezierElements,
    which: &(dyn Fn(usize) -> bool + Sync),
    reach: f64,
) -> (f64, usize) {
    let dim = topo.dim;
    // Inside the side: a point of its edge that slides off the side along the boundary would
    // be measured by its slide.
    let at = |i: usize| (i as f64 + 0.5) / SIDE_SAMPLES as f64;
    topo.boundary_facets
        .par_iter()
        .map(|&f| {
            let e = topo.facet_elements[f as usize][0] as usize;
            if !which(e) {
                return (0.0, 0);
            }
            let Some(s) = (0..2 * dim).find(|&s| topo.element_facet(e, s) == f) else {
                return (0.0, 0);
            };
            let (k, b) = (s / 2, (s % 2) as f64);
            let others: Vec<usize> = (0..dim).filter(|&j| j != k).collect();
            let (m, t) = (map.bezier_net(e), surface.bezier_net(e));
            let samples = samples_per_side(dim);
            // The same net: every distance is 0 (the projection takes no step there).
            let points = net_len(dim);
            if m[..points] == t[..points] {
                return (0.0, samples);
            }
            let mut sum = 0.0;
            for i in 0..samples {
                let mut u = [0.0; 3];
                u[k] = b;
                u[others[0]] = at(i % SIDE_SAMPLES);
                if dim == 3 {
                    u[others[1]] = at(i / SIDE_SAMPLES);
                }
                let p = DVec3::from(eval_net_with_derivatives(dim, &m, u).0);
                sum += nearest_on_side(dim, &t, u, &others, p, reach).0.powi(2);
            }
            (sum, samples)
        })
        .reduce(|| (0.0, 0), |a, b| (a.0 + b.0, a.1 + b.1))
}

/// The samples [`boundary_sq_sum`] counts over the boundary sides of the elements `e` with
/// `which(e)`.
pub(crate) fn boundary_samples(topo: &Topology, which: &dyn Fn(usize) -> bool) -> usize {
    topo.boundary_facets
        .iter()
        .filter(|&&f| which(topo.facet_elements[f as usize][0] as usize))
        .count()
        * samples_per_side(topo.dim)
}

/// The root mean square of `n` squared distances summing to `sum` ([`boundary_sq_sum`]); 0
/// without any.
pub(crate) fn rms(sum: f64, n: usize) -> f64 {
    if n == 0 { 0.0 } else { (sum / n as f64).sqrt() }
}

/// Gauss–Newton steps of [`nearest_on_side`] at most.
const PROJECTION_STEPS: usize = 6;

/// [`nearest_on_side`] stops once the residual's component along the side is at most this
/// share of the residual: the distance it returns is then within `PROJECTION_TOLERANCE`² / 2
/// (relatively) of the distance at the converged point.
const PROJECTION_TOLERANCE: f64 = 1e-3;

/// ... or at most this share of the side's size (the norm of its tangents): a map whose
/// boundary lies on the side (a planar cap, the same fit) only slides along it, and what is
/// left is rounding.
const PROJECTION_FLOOR: f64 = 1e-12;

/// Distance of `p` from the side of the net `t` through `u` that varies in the directions
/// `others` (Gauss–Newton from `u`, the parameters kept in [−`reach`, 1 + `reach`]), and the Gauss–Newton
/// steps taken. The steps stop once the residual is across the side (its component along the
/// side at most [`PROJECTION_TOLERANCE`] of it, or [`PROJECTION_FLOOR`] of the side's size):
/// a further step would move the point found by that component, and the distance by its
/// square; where the residual is 0 (`p` on the side at `u`, the same map) no step is taken.
fn nearest_on_side(
    dim: usize,
    t: &crate::math::BezierNet,
    mut u: [f64; 3],
    others: &[usize],
    p: DVec3,
    reach: f64,
) -> (f64, usize) {
    for steps in 0..PROJECTION_STEPS {
        let (x, d) = eval_net_with_derivatives(dim, t, u);
        let r = p - DVec3::from(x);
        let j: Vec<DVec3> = others.iter().map(|&o| DVec3::from(d[o])).collect();
        let g: Vec<f64> = j.iter().map(|j| j.dot(r)).collect();
        let step = if j.len() == 1 {
            let a = j[0].dot(j[0]);
            if a <= 0.0 {
                break;
            }
            [g[0] / a, 0.0]
        } else {
            let (a, bb, c) = (j[0].dot(j[0]), j[0].dot(j[1]), j[1].dot(j[1]));
            let det = a * c - bb * bb;
            if det <= 0.0 {
                break;
            }
            [(c * g[0] - bb * g[1]) / det, (a * g[1] - bb * g[0]) / det]
        };
        // The squared length of r's component along the side (its projection on the
        // tangents, J (JᵀJ)⁻¹ Jᵀ r) and the side's squared size.
        let along: f64 = step.iter().zip(&g).map(|(s, g)| s * g).sum();
        let size: f64 = j.iter().map(|j| j.length_squared()).sum();
        if along <= PROJECTION_TOLERANCE.powi(2) * r.length_squared()
            || along <= PROJECTION_FLOOR.powi(2) * size
        {
            return (r.length(), steps);
        }
        for (q, &o) in others.iter().enumerate() {
            u[o] = (u[o] + step[q]).clamp(-reach, 1.0 + reach);
        }
    }
    let x = eval_net_with_derivatives(dim, t, u).0;
    ((p - DVec3::from(x)).length(), PROJECTION_STEPS)
}

/// What the marking needs of one boundary side: its vertices by a key common to every
/// process holding them (a vertex index, or a global node tag), its deviation and whether it
/// is over its threshold on a spline element.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct SideFigures {
    /// The side's vertex keys; the first 2^(d−1) are used.
    pub vertices: [u64; 4],
    pub deviation: f64,
    pub over: bool,
}

impl Side {
    /// The side's [`SideFigures`], its vertices keyed by `key`.
    pub(crate) fn figures(
        &self,
        topo: &Topology,
        space: &SplineSpace,
        key: impl Fn(u32) -> u64,
    ) -> SideFigures {
        let mut vertices = [u64::MAX; 4];
        for (k, &v) in vertices
            .iter_mut()
            .zip(topo.facet_vertices(self.facet as usize))
        {
            *k = key(v);
        }
        SideFigures {
            vertices,
            deviation: self.deviation,
            over: space.is_spline(self.element as usize) && self.deviation > self.threshold,
        }
    }
}

/// Which of `sides` are marked: the seeds (over their threshold and more than
/// `NEIGHBOUR_FACTOR` times worse than the best side sharing a vertex) and every over side
/// connected to a seed through over sides. Independent of the sides' order.
pub(crate) fn marked_sides(sides: &[SideFigures]) -> Vec<bool> {
    let keys = |side: &SideFigures| {
        side.vertices
            .into_iter()
            .filter(|&k| k != u64::MAX)
            .collect::<Vec<_>>()
    };
    // The sides at each boundary vertex.
    let mut sides_at: HashMap<u64, Vec<u32>> = HashMap::new();
    for (i, side) in sides.iter().enumerate() {
        for k in keys(side) {
            sides_at.entry(k).or_default().push(i as u32);
        }
    }
    let around = |i: usize| {
        keys(&sides[i])
            .into_iter()
            .flat_map(|k| sides_at[&k].iter().map(|&j| j as usize))
            .collect::<Vec<_>>()
    };
    // Seeds: sides over their threshold and much worse than the best side sharing a vertex.
    let seeds: Vec<usize> = (0..sides.len())
        .filter(|&i| {
            let best = around(i)
                .into_iter()
                .filter(|&j| j != i)
                .map(|j| sides[j].deviation)
                .fold(f64::INFINITY, f64::min);
            sides[i].over && sides[i].deviation > NEIGHBOUR_FACTOR * best
        })
        .collect();
    // From each seed along the boundary through every side over its threshold: a run of
    // misfits is marked whole, not peeled from its ends one fit at a time; a run longer than
    // `MAX_RUN` is not a local failure and is left as it is.
    let mut seen = vec![false; sides.len()];
    let mut marked = vec![false; sides.len()];
    for &seed in &seeds {
        if seen[seed] {
            continue;
        }
        seen[seed] = true;
        let (mut run, mut stack) = (vec![seed], vec![seed]);
        while let Some(i) = stack.pop() {
            for j in around(i) {
                if !seen[j] && sides[j].over {
                    seen[j] = true;
                    run.push(j);
                    stack.push(j);
                }
            }
        }
        if run.len() <= MAX_RUN {
            for i in run {
                marked[i] = true;
            }
        }
    }
    marked
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A closed ring of `n` sides, side i from vertex i to i + 1, all over their threshold
    /// except side 0, which fits 100 times better (a Q2 side).
    fn ring(n: usize) -> Vec<SideFigures> {
        (0..n)
            .map(|i| SideFigures {
                vertices: [i as u64, ((i + 1) % n) as u64, u64::MAX, u64::MAX],
                deviation: if i == 0 { 0.01 } else { 1.0 },
                over: i != 0,
            })
            .collect()
    }

    /// The nearest point of the paraboloid z = x² + y² / 2 (2D: the parabola y = x² at z = 0)
    /// to `p` over x, y ∈ [−1, 1], by a grid search zoomed in ten times (independent of the
    /// Bernstein nets and of Gauss–Newton): its distance.
    fn nearest_on_paraboloid(dim: usize, p: DVec3) -> f64 {
        let at = |x: f64, y: f64| {
            if dim == 2 {
                DVec3::new(x, x * x, 0.0)
            } else {
                DVec3::new(x, y, x * x + y * y / 2.0)
            }
        };
        let (mut c, mut half) = ([0.0, 0.0], 1.0);
        let n = 40;
        for _ in 0..12 {
            let mut best = (f64::INFINITY, c);
            for i in 0..=n {
                for j in 0..=if dim == 2 { 0 } else { n } {
                    let x = (c[0] - half + 2.0 * half * i as f64 / n as f64).clamp(-1.0, 1.0);
                    let y = (c[1] - half + 2.0 * half * j as f64 / n as f64).clamp(-1.0, 1.0);
                    let y = if dim == 2 { 0.0 } else { y };
                    let d = (p - at(x, y)).length();
                    if d < best.0 {
                        best = (d, [x, y]);
                    }
                }
            }
            c = best.1;
            half /= 8.0;
        }
        (p - at(c[0], c[1])).length()
    }

    /// The quadratic net whose side u_{last} = 0 is that paraboloid (x = 2u₀ − 1, y = 2u₁ − 1),
    /// the rest of the element above it.
    fn paraboloid_net(dim: usize) -> crate::math::BezierNet {
        let mut net = [[0.0; 3]; 27];
        for (i, point) in net.iter_mut().enumerate().take(net_len(dim)) {
            let l = [i % 3, (i / 3) % 3, i / 9];
            let x = l[0] as f64 - 1.0;
            // The Bézier points of x² over [−1, 1]: 1, −1, 1.
            let sq = |l: usize| if l == 1 { -1.0 } else { 1.0 };
            *point = if dim == 2 {
                [x, sq(l[0]) + l[1] as f64, 0.0]
            } else {
                let y = l[1] as f64 - 1.0;
                [x, y, sq(l[0]) + sq(l[1]) / 2.0 + l[2] as f64]
            };
        }
        net
    }

    #[test]
    fn the_projection_stops_early_at_the_nearest_point() {
        let mut early = 0;
        for dim in [2, 3] {
            let t = paraboloid_net(dim);
            let others: Vec<usize> = (0..dim - 1).collect();
            // Points off the side at parameters v by h along the normal, projected from u
            // (slid along the side by `slide`, as a second fit's parametrisation is).
            for (v, h, slide) in [
                (0.3, 1e-3, 0.02),
                (0.7, -2e-2, -0.05),
                (0.55, 1e-6, 0.001),
                (0.45, 0.0, 0.03),
                (0.2, 0.1, 0.1),
            ] {
                let mut u = [v, 0.6 * v, 0.0];
                u[dim - 1] = 0.0;
                let (x, d) = eval_net_with_derivatives(dim, &t, u);
                let normal = if dim == 2 {
                    DVec3::from(d[0]).cross(DVec3::Z)
                } else {
                    DVec3::from(d[0]).cross(DVec3::from(d[1]))
                }
                .normalize();
                let p = DVec3::from(x) + h * normal;
                for &o in &others {
                    u[o] += slide;
                }
                let (distance, steps) = nearest_on_side(dim, &t, u, &others, p, 0.0);
                let exact = nearest_on_paraboloid(dim, p);
                assert!(
                    (distance - exact).abs() <= 1e-6 * exact + 1e-11,
                    "{dim}D v {v} h {h} slide {slide}: {distance:e} against {exact:e} ({steps} steps)"
                );
                early += usize::from(steps < PROJECTION_STEPS);
            }
            // The same point: no step.
            let mut u = [0.4, 0.3, 0.0];
            u[dim - 1] = 0.0;
            let p = DVec3::from(eval_net_with_derivatives(dim, &t, u).0);
            assert_eq!(nearest_on_side(dim, &t, u, &others, p, 0.0), (0.0, 0));
        }
        // The near and on-side points stop before the last step.
        assert!(early >= 8, "{early} of 10 stopped early");
    }

    /// A point of the side's patch beyond the side (a slide along the boundary past its edge)
    /// is at distance 0 once the search reaches that far, and at its slide within the side.
    #[test]
    fn a_slide_past_the_side_is_not_distance_within_the_reach() {
        for dim in [2, 3] {
            let t = paraboloid_net(dim);
            let others: Vec<usize> = (0..dim - 1).collect();
            let mut beyond = [1.3, 0.5, 0.0];
            beyond[dim - 1] = 0.0;
            let p = DVec3::from(eval_net_with_derivatives(dim, &t, beyond).0);
            let mut u = [0.9, 0.5, 0.0];
            u[dim - 1] = 0.0;
            let within = nearest_on_side(dim, &t, u, &others, p, 0.0).0;
            let reached = nearest_on_side(dim, &t, u, &others, p, SLIDE_REACH).0;
            assert!(within > 0.1, "{dim}D: {within:e} within the side");
            assert!(reached < 1e-9, "{dim}D: {reached:e} within the reach");
        }
    }

    #[test]
    fn a_short_run_next_to_a_good_side_is_marked_whole_and_a_long_one_not() {
        let short = marked_sides(&ring(MAX_RUN));
        assert!(!short[0] && short[1..].iter().all(|&m| m), "{short:?}");
        let long = marked_sides(&ring(MAX_RUN + 2));
        assert!(long.iter().all(|&m| !m), "{long:?}");
        // The marks are the sides', whatever their order (the distributed run gathers them
        // rank by rank).
        let mut sides = ring(MAX_RUN);
        sides.reverse();
        let mut reversed = marked_sides(&sides);
        reversed.reverse();
        assert_eq!(reversed, short);
    }
}
