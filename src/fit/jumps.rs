//! The fitted map's kinks at C⁰ facets, lowered after the fit (`--facet-smoothing W`).
//!
//! The spline space is C¹ across the facets between two spline elements and only C⁰ where a
//! Q2 element (irregular, at a boundary kink, demoted) meets another element: there the fit
//! leaves the input's kinks, since its targets inside the mesh are the straight elements.
//!
//! Input: a fit space, the linear mesh and its topology (the input's, periodic seams apart),
//! which elements are spline elements, the fitted control points C* and a weight W > 0.
//! Output: control points C that minimise
//!
//!   W Σ_f Σ_p ‖j_f(p)‖² + Σ_{i movable} ‖C_i − C*_i‖²,
//!   j_f(p) = (ℓ_b d_a(p) + ℓ_a d_b(p)) / (ℓ_a + ℓ_b),
//!
//! over the interior facets f with a non-spline element on either side, at 3 (2D) or 3 × 3
//! (3D) points p of the facet (¼, ½, ¾ of its bilinear parameters, placed in both elements by
//! the facet's vertices). d_x is element x's derivative transversal to the facet, pointing out
//! of x, and ℓ_x = ‖d_x‖ at C* (fixed, so j is linear in C): j = 0 exactly where the two
//! elements' transversal derivatives are opposite, i.e. the map is G¹ across the facet with
//! the elements' own size ratio, so graded cells are not pulled to equal sizes. j has the unit
//! of length, as the anchor, so W is dimensionless.
//!
//! Movable: the control points in some j's rows that carry no Bernstein point of a boundary
//! facet (the boundary is the fit's exactly, as in the energy stage); elements with periodic
//! frames or seam offsets add no rows. One SPD system (I + W JᵀJ) δ = −W Jᵀ J C*, solved by
//! CG, gives C = C* + δ on the movable points.
//!
//! **Quality kept inside the blend's rules.** Straightening a kink bends the elements beside
//! it, and the blend that follows holds back every element its rules reject (with the
//! neighbours that share its points): a smoothing judged only by the jumps raised the
//! held-back share above 10 % on meshes whose fit was accepted. So each element must keep,
//! sampled over {0, ¼, ½, ¾, 1}^d, a Jacobian ratio and a scaled Jacobian of at least
//! `MARGIN` × the blend's targets for it (max(q_min · r_S, q_p · min(r_S, P)), r_S the
//! straight element's corner ratio and P the straight mesh's 1st percentile; the same of the
//! scaled Jacobian, [`JumpGuard`]) and at least the straight mesh's smallest values, but
//! never more than the fit's own. An element already below MARGIN × a target at the fit is
//! at risk (the blend holds it back, or may): its points and those of every element sharing
//! one are frozen before the solve, so the blend's reduction of it meets neighbours as the
//! fit left them. After the one solve, the move of every point of an element below its
//! needs is halved, again and again (after `HALVINGS` it is dropped), until no element is;
//! an element all of whose points are back at the fit keeps its needs, so this ends.

//! Invariant: the result is still only a proposal; the certificate and the blend that follow
//! the fit decide per element.

use super::FitSpace;
use crate::math::bernstein::{bernstein2, bernstein2_derivative, net_len};
use crate::math::reference::{HEX_SIDES, HEX_VERTEX_PARAMS, QUAD_SIDES};
use crate::mesh::LinearMesh;
use crate::mesh::topology::{NONE, Topology};
use crate::solve::{CgError, CgParams};
use rayon::prelude::*;

/// What the smoothing did.
#[derive(Clone, Copy, Debug, Default, serde::Serialize)]
pub struct JumpInfo {
    /// Interior facets with a non-spline element on a side (rows came from these).
    pub facets: usize,
    /// Control points moved.
    pub moved: usize,
    /// Root mean square of ‖j‖ over the facet points, before.
    pub rms_before: f64,
    /// The same, after.
    pub rms_after: f64,
    /// CG iterations of the solves (one per round).
    pub iterations: usize,
    /// Elements within the margin of the blend's rules at the fit, or outside them: their
    /// points and their neighbours' stay at the fit.
    pub at_risk_elements: usize,
    /// Elements a move took below their needs (the moves of their points then halved),
    /// counted once per halving.
    pub frozen_elements: usize,
    /// Wall time of the smoothing, set by the caller (0 when it is not).
    pub seconds: f64,
}

/// One row of J: control point ids (sorted, distinct) and coefficients.
struct Row {
    cols: Vec<u32>,
    vals: Vec<f64>,
}

/// The facet parameters of the points: ¼, ½, ¾ along each of the facet's directions.
const AT: [f64; 3] = [0.25, 0.5, 0.75];

/// The blend's element rules the smoothing keeps (the certified blend's q_min and
/// q_p): a move stands only where every element it shapes stays inside them.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct JumpGuard {
    /// q_min: an element keeps this fraction of its straight ratio and scaled Jacobian.
    pub min_quality_fraction: f64,
    /// q_p: and this fraction of min(its straight value, the straight mesh's 1st percentile).
    pub percentile_quality_fraction: f64,
}

impl Default for JumpGuard {
    fn default() -> Self {
        JumpGuard {
            min_quality_fraction: 0.55,
            percentile_quality_fraction: 0.85,
        }
    }
}

/// Lower the kinks of `c` (the fitted control points) at the C⁰ facets, in place, keeping
/// every element inside `guard`'s rules (or, where the fit is not, no poorer than the fit).
pub fn smooth_facet_jumps(
    space: &dyn FitSpace,
    mesh: &LinearMesh,
    topo: &Topology,
    is_spline: &(dyn Fn(usize) -> bool + Sync),
    weight: f64,
    guard: &JumpGuard,
    c: &mut [[f64; 3]],
) -> Result<JumpInfo, CgError> {
    let facets: Vec<usize> = (0..topo.n_facets())
        .filter(|&f| {
            let [a, b] = topo.facet_elements[f];
            b != NONE
                && !(is_spline(a as usize) && is_spline(b as usize))
                && [a, b].iter().all(|&e| {
                    space.frames(e as usize).is_none() && space.net_shift(e as usize).is_none()
                })
        })
        .collect();
    let rows: Vec<Row> = facets
        .par_iter()
        .flat_map_iter(|&f| facet_rows(space, mesh, topo, f, c))
        .collect();
    let mut frozen = boundary_points(space, topo, c.len());
    let jc = |c: &[[f64; 3]]| -> Vec<[f64; 3]> { rows.par_iter().map(|r| apply(r, c)).collect() };
    let rms = |j: &[[f64; 3]]| {
        let s: f64 = j.iter().map(|v| v.iter().map(|x| x * x).sum::<f64>()).sum();
        (s / j.len().max(1) as f64).sqrt()
    };
    let j0 = jc(c);
    let mut info = JumpInfo {
        facets: facets.len(),
        rms_before: rms(&j0),
        rms_after: rms(&j0),
        ..Default::default()
    };
    if rows.is_empty() {
        return Ok(info);
    }
    let dim = topo.dim;
    let start = c.to_vec();
    // The elements each control point shapes, and the quality each element must keep.
    let supports = Supports::new(space);
    let needs = Needs::new(space, mesh, guard, &start);
    // Elements at risk at the fit (outside the rules, or within MARGIN of them) are held back,
    // or may be: their points and those of every element sharing one stay at the fit, so
    // the blend's reduction of them meets neighbours as the fit left them.
    for e in (0..space.n_elements()).filter(|&e| needs.at_risk[e]) {
        info.at_risk_elements += 1;
        for &id in supports.element(e) {
            for &n in supports.of(id as usize) {
                for &q in supports.element(n as usize) {
                    frozen[q as usize] = true;
                }
            }
        }
    }
    let (movable, delta, iterations) = solve(&rows, &j0, &frozen, weight)?;
    info.iterations = iterations;
    // The move of each movable point, halved for every element it takes below its needs
    // ([`HALVINGS`] times, then dropped), until no element is.
    let mut slot = vec![u32::MAX; c.len()];
    for (i, &id) in movable.iter().enumerate() {
        slot[id] = i as u32;
    }
    let mut halved = vec![0u32; movable.len()];
    loop {
        for (i, &id) in movable.iter().enumerate() {
            let share = if halved[i] > HALVINGS {
                0.0
            } else {
                0.5f64.powi(halved[i] as i32)
            };
            for k in 0..3 {
                c[id][k] = start[id][k] + share * delta[i][k];
            }
        }
        let poorer = needs.poorer(space, dim, &supports, &movable, c);
        if poorer.is_empty() {
            break;
        }
        info.frozen_elements += poorer.len();
        let mut points: Vec<u32> = poorer
            .iter()
            .flat_map(|&e| supports.element(e).iter().copied())
            .filter(|&id| slot[id as usize] != u32::MAX)
            .collect();
        points.sort_unstable();
        points.dedup();
        for id in points {
            halved[slot[id as usize] as usize] += 1;
        }
    }
    info.moved = (0..c.len()).filter(|&i| c[i] != start[i]).count();
    info.rms_after = rms(&jc(c));
    Ok(info)
}

/// Halvings of a point's move before it is dropped ([`smooth_facet_jumps`]).
const HALVINGS: u32 = 4;

/// A moved element keeps at least this multiple of the rules' targets: the rules are judged
/// on certified bounds, the guard on samples.
const MARGIN: f64 = 1.1;

/// The sampled Jacobian ratio and scaled Jacobian each element must keep.
struct Needs {
    ratio: Vec<f64>,
    scaled: Vec<f64>,
    /// At the fit, below [`MARGIN`] × a target (held back by the blend, or close to it).
    at_risk: Vec<bool>,
}

impl Needs {
    /// Per element: the rules' targets (by the straight element's corner ratio r_S and its
    /// sampled scaled Jacobian s_S, as in the blend) times [`MARGIN`], at most the fit's own
    /// values (an element the fit leaves outside the rules must only not get poorer), and at
    /// least the straight mesh's smallest values (the mesh's minimum is not lowered).
    fn new(space: &dyn FitSpace, mesh: &LinearMesh, guard: &JumpGuard, fit: &[[f64; 3]]) -> Self {
        let dim = mesh.dim;
        let n = space.n_elements();
        let straight: Vec<(f64, f64)> = (0..n)
            .into_par_iter()
            .map(|e| {
                let x = mesh.element_coords(e);
                let npe = mesh.nodes_per_element();
                let (mut jac, mut sj) = ([0.0; 8], [0.0; 8]);
                crate::mesh::linear::corner_jacobians(
                    dim,
                    &x[..npe],
                    &mut jac[..npe],
                    &mut sj[..npe],
                );
                let lo = jac[..npe].iter().copied().fold(f64::INFINITY, f64::min);
                let hi = jac[..npe].iter().copied().fold(f64::NEG_INFINITY, f64::max);
                (lo / hi, quality(dim, &straight_net(mesh, e)).scaled)
            })
            .collect();
        let low = |k: usize| -> (f64, f64) {
            let mut v: Vec<f64> = straight
                .iter()
                .map(|s| if k == 0 { s.0 } else { s.1 })
                .collect();
            v.sort_by(f64::total_cmp);
            (v[0], v.get(v.len() / 100).copied().unwrap_or(1.0))
        };
        let ((min_r, p_r), (min_s, p_s)) = (low(0), low(1));
        let (qm, qp) = (
            guard.min_quality_fraction,
            guard.percentile_quality_fraction,
        );
        let target = |s: f64, p: f64| (qm * s).max(qp * s.min(p));
        let per: Vec<(f64, f64, bool)> = (0..n)
            .into_par_iter()
            .map(|e| {
                let q = quality(dim, &space.bezier_net_with(e, fit));
                let (r, s) = straight[e];
                let (tr, ts) = (MARGIN * target(r, p_r), MARGIN * target(s, p_s));
                (
                    q.ratio.min(tr.max(min_r)),
                    q.scaled.min(ts.max(min_s)),
                    !(q.ratio >= tr && q.scaled >= ts),
                )
            })
            .collect();
        Needs {
            ratio: per.iter().map(|p| p.0).collect(),
            scaled: per.iter().map(|p| p.1).collect(),
            at_risk: per.iter().map(|p| p.2).collect(),
        }
    }

    /// The elements around the `moved` points that `c` takes below their needs.
    fn poorer(
        &self,
        space: &dyn FitSpace,
        dim: usize,
        supports: &Supports,
        moved: &[usize],
        c: &[[f64; 3]],
    ) -> Vec<usize> {
        let mut touched: Vec<usize> = moved
            .iter()
            .flat_map(|&id| supports.of(id).iter().map(|&e| e as usize))
            .collect();
        touched.sort_unstable();
        touched.dedup();
        touched
            .into_par_iter()
            .filter(|&e| {
                let q = quality(dim, &space.bezier_net_with(e, c));
                !(q.ratio >= self.ratio[e] && q.scaled >= self.scaled[e])
            })
            .collect()
    }
}

/// The straight-sided elevation's Bernstein net of element `e`: its multilinear map at the
/// points {0, ½, 1}^d.
fn straight_net(mesh: &LinearMesh, e: usize) -> crate::math::bernstein::BezierNet {
    let dim = mesh.dim;
    let x = mesh.element_coords(e);
    let corners = if dim == 2 { 4 } else { 8 };
    let mut net = [[0.0; 3]; 27];
    for (p, out) in net.iter_mut().enumerate().take(net_len(dim)) {
        let u = [p % 3, (p / 3) % 3, p / 9].map(|i| i as f64 / 2.0);
        for (v, xv) in x.iter().enumerate().take(corners) {
            let w: f64 = (0..dim)
                .map(|k| {
                    let c = f64::from(HEX_VERTEX_PARAMS[v][k]);
                    c * u[k] + (1.0 - c) * (1.0 - u[k])
                })
                .product();
            for k in 0..3 {
                out[k] += w * xv[k];
            }
        }
    }
    net
}

/// An element's sampled quality: min/max det J and the smallest scaled Jacobian over the
/// lattice {0, ¼, ½, ¾, 1}^d (the blend's lattice), by sum factorisation of the net.
#[derive(Clone, Copy, Debug)]
struct Quality {
    ratio: f64,
    scaled: f64,
}

fn quality(dim: usize, net: &crate::math::bernstein::BezierNet) -> Quality {
    const T: [f64; 5] = [0.0, 0.25, 0.5, 0.75, 1.0];
    let b = T.map(bernstein2);
    let d = T.map(bernstein2_derivative);
    let layers = if dim == 2 { 1 } else { 3 };
    type Plane = [[[[f64; 3]; 3]; 3]; 5];
    // x contracted: value and x-derivative, by (sample i, control y, control z).
    let (mut bx, mut dx): (Plane, Plane) = ([[[[0.0; 3]; 3]; 3]; 5], [[[[0.0; 3]; 3]; 3]; 5]);
    for i in 0..5 {
        for z in 0..layers {
            for y in 0..3 {
                for a in 0..3 {
                    let p = net[9 * z + 3 * y + a];
                    for k in 0..3 {
                        bx[i][y][z][k] += b[i][a] * p[k];
                        dx[i][y][z][k] += d[i][a] * p[k];
                    }
                }
            }
        }
    }
    // y contracted: ∂x, ∂y and the value, by (sample i, sample j, control z).
    type Line = [[[[f64; 3]; 3]; 5]; 5];
    let zero: Line = [[[[0.0; 3]; 3]; 5]; 5];
    let (mut ux, mut uy, mut u0) = (zero, zero, zero);
    for i in 0..5 {
        for j in 0..5 {
            for z in 0..layers {
                for c in 0..3 {
                    for k in 0..3 {
                        ux[i][j][z][k] += b[j][c] * dx[i][c][z][k];
                        uy[i][j][z][k] += d[j][c] * bx[i][c][z][k];
                        u0[i][j][z][k] += b[j][c] * bx[i][c][z][k];
                    }
                }
            }
        }
    }
    let mut q = Samples::new();
    let samples = if dim == 2 { 1 } else { 5 };
    for i in 0..5 {
        for j in 0..5 {
            for s in 0..samples {
                let mut g = [[0.0; 3]; 3];
                if dim == 2 {
                    g[0] = ux[i][j][0];
                    g[1] = uy[i][j][0];
                } else {
                    for c in 0..3 {
                        for k in 0..3 {
                            g[0][k] += b[s][c] * ux[i][j][c][k];
                            g[1][k] += b[s][c] * uy[i][j][c][k];
                            g[2][k] += d[s][c] * u0[i][j][c][k];
                        }
                    }
                }
                q.add(dim, &g);
            }
        }
    }
    q.quality()
}

/// The running min/max det J and smallest scaled Jacobian of an element's samples.
struct Samples {
    lo: f64,
    hi: f64,
    scaled: f64,
}

impl Samples {
    fn new() -> Self {
        Samples {
            lo: f64::INFINITY,
            hi: f64::NEG_INFINITY,
            scaled: f64::INFINITY,
        }
    }

    /// Adds the sample whose Jacobian has the reference-axis derivatives `g` as rows (in 2D
    /// the first two; the third is not read).
    fn add(&mut self, dim: usize, g: &[[f64; 3]; 3]) {
        let det = if dim == 2 {
            g[0][0] * g[1][1] - g[0][1] * g[1][0]
        } else {
            crate::math::linalg::det3(g)
        };
        let lengths: f64 = g[..dim].iter().map(|v| norm(*v)).product();
        self.lo = self.lo.min(det);
        self.hi = self.hi.max(det);
        self.scaled = self.scaled.min(det / lengths);
    }

    fn quality(&self) -> Quality {
        Quality {
            ratio: if self.hi > 0.0 {
                self.lo / self.hi
            } else {
                f64::NEG_INFINITY
            },
            scaled: self.scaled,
        }
    }
}

/// Each element's distinct control points, and each control point's elements.
struct Supports {
    element: Csr,
    point: Csr,
}

impl Supports {
    fn new(space: &dyn FitSpace) -> Self {
        let per: Vec<Vec<u32>> = (0..space.n_elements())
            .into_par_iter()
            .map_init(
                || (Vec::new(), Vec::new(), Vec::new()),
                |(offsets, cols, weights), e| {
                    space.element_rows(e, offsets, cols, weights);
                    let mut ids: Vec<u32> = cols
                        .iter()
                        .zip(weights.iter())
                        .filter(|p| *p.1 != 0.0)
                        .map(|p| *p.0)
                        .collect();
                    ids.sort_unstable();
                    ids.dedup();
                    ids
                },
            )
            .collect();
        let mut element = Csr::default();
        for ids in per {
            element.vals.extend(std::iter::repeat_n(1.0, ids.len()));
            element.cols.extend(ids);
            element.offsets.push(element.cols.len());
        }
        let point = element.transpose(space.control_points().len());
        Supports { element, point }
    }

    fn element(&self, e: usize) -> &[u32] {
        &self.element.cols[self.element.offsets[e]..self.element.offsets[e + 1]]
    }

    fn of(&self, id: usize) -> &[u32] {
        &self.point.cols[self.point.offsets[id]..self.point.offsets[id + 1]]
    }
}

/// The minimiser's move δ of the points in J's rows that are not `frozen`: (I + W JᵀJ) δ =
/// −W Jᵀ J C* over them, with J C* = `j0`. Returns the points, their moves and the CG's
/// iterations.
fn solve(rows: &[Row], j0: &[[f64; 3]], frozen: &[bool], weight: f64) -> Result<Move, CgError> {
    // Movable control points, numbered in id order.
    let mut slot = vec![u32::MAX; frozen.len()];
    for r in rows {
        for &id in &r.cols {
            if !frozen[id as usize] {
                slot[id as usize] = 0;
            }
        }
    }
    let mut movable = Vec::new();
    for (id, s) in slot.iter_mut().enumerate() {
        if *s == 0 {
            *s = movable.len() as u32;
            movable.push(id);
        }
    }
    if movable.is_empty() {
        return Ok((movable, Vec::new(), 0));
    }
    // J restricted to the movable points (compact columns) and its transpose; the operator
    // I + W JᵀJ is applied without forming JᵀJ (a facet's rows couple two elements' 2 × 27
    // points, so JᵀJ has ~50 times J's entries).
    let mut j = Csr::default();
    for row in rows {
        for (&id, &v) in row.cols.iter().zip(&row.vals) {
            let s = slot[id as usize];
            if s != u32::MAX {
                j.cols.push(s);
                j.vals.push(v);
            }
        }
        j.offsets.push(j.cols.len());
    }
    let jt = j.transpose(movable.len());
    let op = Smoothing { j, jt, weight };
    let mut b = vec![[0.0; 3]; movable.len()];
    op.jt.mul(j0, &mut b);
    b.iter_mut().flatten().for_each(|v| *v *= -weight);
    let mut delta = vec![[0.0; 3]; movable.len()];
    let params = CgParams {
        rel_tol: 1e-8,
        preconditioner: crate::solve::CgPreconditioner::Jacobi,
        ..CgParams::default()
    };
    let cg = crate::solve::pcg(&op, &b, &mut delta, &params, |_, _| {})?;
    Ok((movable, delta, cg.iterations))
}

/// The movable points, their moves and the CG's iterations ([`solve`]).
type Move = (Vec<usize>, Vec<[f64; 3]>, usize);

/// A sparse matrix by rows.
struct Csr {
    offsets: Vec<usize>,
    cols: Vec<u32>,
    vals: Vec<f64>,
}

impl Default for Csr {
    fn default() -> Self {
        Csr {
            offsets: vec![0],
            cols: Vec::new(),
            vals: Vec::new(),
        }
    }
}

impl Csr {
    fn rows(&self) -> usize {
        self.offsets.len() - 1
    }

    /// The transpose, `n` its rows.
    fn transpose(&self, n: usize) -> Csr {
        let mut offsets = vec![0usize; n + 1];
        for &c in &self.cols {
            offsets[c as usize + 1] += 1;
        }
        for i in 0..n {
            offsets[i + 1] += offsets[i];
        }
        let mut at = offsets.clone();
        let mut cols = vec![0u32; self.cols.len()];
        let mut vals = vec![0.0; self.cols.len()];
        for r in 0..self.rows() {
            for k in self.offsets[r]..self.offsets[r + 1] {
                let c = self.cols[k] as usize;
                cols[at[c]] = r as u32;
                vals[at[c]] = self.vals[k];
                at[c] += 1;
            }
        }
        Csr {
            offsets,
            cols,
            vals,
        }
    }

    /// y = A x.
    fn mul(&self, x: &[[f64; 3]], y: &mut [[f64; 3]]) {
        y.par_iter_mut().enumerate().for_each(|(r, y)| {
            let mut s = [0.0; 3];
            for k in self.offsets[r]..self.offsets[r + 1] {
                let (c, v) = (self.cols[k] as usize, self.vals[k]);
                for d in 0..3 {
                    s[d] += v * x[c][d];
                }
            }
            *y = s;
        });
    }
}

/// I + W JᵀJ on the movable points.
struct Smoothing {
    j: Csr,
    jt: Csr,
    weight: f64,
}

impl crate::solve::LinOp for Smoothing {
    fn nrows(&self) -> usize {
        self.jt.rows()
    }

    fn apply(&self, x: &[[f64; 3]], y: &mut [[f64; 3]]) {
        let mut jx = vec![[0.0; 3]; self.j.rows()];
        self.j.mul(x, &mut jx);
        self.jt.mul(&jx, y);
        y.par_iter_mut().zip(x).for_each(|(y, x)| {
            for d in 0..3 {
                y[d] = x[d] + self.weight * y[d];
            }
        });
    }

    fn diagonal(&self) -> Vec<f64> {
        (0..self.jt.rows())
            .map(|i| {
                let s: f64 = self.jt.vals[self.jt.offsets[i]..self.jt.offsets[i + 1]]
                    .iter()
                    .map(|v| v * v)
                    .sum();
                1.0 + self.weight * s
            })
            .collect()
    }
}

fn apply(r: &Row, c: &[[f64; 3]]) -> [f64; 3] {
    let mut s = [0.0; 3];
    for (&id, &v) in r.cols.iter().zip(&r.vals) {
        for d in 0..3 {
            s[d] += v * c[id as usize][d];
        }
    }
    s
}

/// Control points with a non-zero weight at a Bernstein point of a boundary facet.
fn boundary_points(space: &dyn FitSpace, topo: &Topology, n: usize) -> Vec<bool> {
    let dim = topo.dim;
    let nb = net_len(dim);
    let (mut offsets, mut cols, mut weights) = (Vec::new(), Vec::new(), Vec::new());
    let mut frozen = vec![false; n];
    for e in 0..space.n_elements() {
        let open: Vec<usize> = (0..2 * dim)
            .filter(|&s| topo.neighbor(e, s) == NONE)
            .collect();
        if open.is_empty() {
            continue;
        }
        space.element_rows(e, &mut offsets, &mut cols, &mut weights);
        for a in 0..nb {
            let l = [a % 3, (a / 3) % 3, a / 9];
            if !open.iter().any(|&s| l[s / 2] == 2 * (s % 2)) {
                continue;
            }
            for k in offsets[a]..offsets[a + 1] {
                if weights[k] != 0.0 {
                    frozen[cols[k] as usize] = true;
                }
            }
        }
    }
    frozen
}

/// The local reference corners of facet `f`'s vertices in element `e` (None when a vertex of
/// the facet is not one of `e`'s corners: a degenerate or non-conforming pair).
fn corners_in(mesh: &LinearMesh, e: usize, vertices: &[u32]) -> Option<Vec<[f64; 3]>> {
    let own = mesh.element(e);
    vertices
        .iter()
        .map(|v| {
            let i = own.iter().position(|w| w == v)?;
            Some(HEX_VERTEX_PARAMS[i].map(f64::from))
        })
        .collect()
}

/// J's rows of facet `f` (one per facet point), ℓ taken at `c`.
fn facet_rows(
    space: &dyn FitSpace,
    mesh: &LinearMesh,
    topo: &Topology,
    f: usize,
    c: &[[f64; 3]],
) -> Vec<Row> {
    let dim = topo.dim;
    let [a, b] = topo.facet_elements[f].map(|e| e as usize);
    let [sa, sb] = topo.facet_sides[f].map(usize::from);
    let local: Vec<usize> = if dim == 2 {
        QUAD_SIDES[sa].to_vec()
    } else {
        HEX_SIDES[sa].to_vec()
    };
    let vertices: Vec<u32> = local.iter().map(|&i| mesh.element(a)[i]).collect();
    let (Some(ra), Some(rb)) = (
        corners_in(mesh, a, &vertices),
        corners_in(mesh, b, &vertices),
    ) else {
        return Vec::new();
    };
    // Bilinear (3D: corners in cycle order at (0,0), (1,0), (1,1), (0,1)) or linear weights.
    let points: Vec<Vec<f64>> = if dim == 2 {
        AT.iter().map(|&t| vec![1.0 - t, t]).collect()
    } else {
        AT.iter()
            .flat_map(|&s| {
                AT.iter()
                    .map(move |&t| vec![(1.0 - s) * (1.0 - t), s * (1.0 - t), s * t, (1.0 - s) * t])
            })
            .collect()
    };
    let rows_a = ElementRowsOf::new(space, a);
    let rows_b = ElementRowsOf::new(space, b);
    points
        .iter()
        .filter_map(|phi| {
            let at = |r: &[[f64; 3]]| -> [f64; 3] {
                std::array::from_fn(|k| phi.iter().zip(r).map(|(w, x)| w * x[k]).sum())
            };
            let da = rows_a.transversal(dim, sa, at(&ra));
            let db = rows_b.transversal(dim, sb, at(&rb));
            let (la, lb) = (norm(apply(&da, c)), norm(apply(&db, c)));
            if !(la > 0.0 && lb > 0.0) {
                return None;
            }
            Some(combine(&da, lb / (la + lb), &db, la / (la + lb)))
        })
        .collect()
}

fn norm(v: [f64; 3]) -> f64 {
    (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt()
}

/// wa · ra + wb · rb, columns merged.
fn combine(ra: &Row, wa: f64, rb: &Row, wb: f64) -> Row {
    let mut all: Vec<(u32, f64)> = ra
        .cols
        .iter()
        .zip(&ra.vals)
        .map(|(&c, &v)| (c, wa * v))
        .chain(rb.cols.iter().zip(&rb.vals).map(|(&c, &v)| (c, wb * v)))
        .collect();
    all.sort_unstable_by_key(|p| p.0);
    let mut row = Row {
        cols: Vec::new(),
        vals: Vec::new(),
    };
    for (c, v) in all {
        if row.cols.last() == Some(&c) {
            *row.vals.last_mut().unwrap() += v;
        } else {
            row.cols.push(c);
            row.vals.push(v);
        }
    }
    row
}

/// An element's extraction rows, kept for its facet points.
struct ElementRowsOf {
    offsets: Vec<usize>,
    cols: Vec<u32>,
    weights: Vec<f64>,
}

impl ElementRowsOf {
    fn new(space: &dyn FitSpace, e: usize) -> Self {
        let (mut offsets, mut cols, mut weights) = (Vec::new(), Vec::new(), Vec::new());
        space.element_rows(e, &mut offsets, &mut cols, &mut weights);
        ElementRowsOf {
            offsets,
            cols,
            weights,
        }
    }

    /// The row of the derivative transversal to local side `side`, out of the element, at the
    /// reference point `u`, over control points.
    fn transversal(&self, dim: usize, side: usize, u: [f64; 3]) -> Row {
        let k = side / 2;
        let sign = if side % 2 == 1 { 1.0 } else { -1.0 };
        let b = [bernstein2(u[0]), bernstein2(u[1]), bernstein2(u[2])];
        let db = [
            bernstein2_derivative(u[0]),
            bernstein2_derivative(u[1]),
            bernstein2_derivative(u[2]),
        ];
        let mut all: Vec<(u32, f64)> = Vec::new();
        for p in 0..net_len(dim) {
            let l = [p % 3, (p / 3) % 3, p / 9];
            let mut g = sign;
            for j in 0..dim {
                g *= if j == k { db[j][l[j]] } else { b[j][l[j]] };
            }
            if g == 0.0 {
                continue;
            }
            for q in self.offsets[p]..self.offsets[p + 1] {
                all.push((self.cols[q], g * self.weights[q]));
            }
        }
        combine(
            &Row {
                cols: all.iter().map(|p| p.0).collect(),
                vals: all.iter().map(|p| p.1).collect(),
            },
            1.0,
            &Row {
                cols: Vec::new(),
                vals: Vec::new(),
            },
            0.0,
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math::bernstein::eval_net_with_derivatives;
    use crate::mesh::generate::{grid_2d, grid_3d};
    use crate::spline::SplineSpace;

    /// Every element a constrained Q2 element: every interior facet is C⁰.
    fn all_q2(mesh: &LinearMesh) -> (Topology, SplineSpace) {
        let topo = Topology::build(mesh);
        let space = SplineSpace::build_with_demoted(mesh, &topo, &vec![true; mesh.n_elements()]);
        (topo, space)
    }

    /// The same samples evaluated point by point.
    fn quality_by_points(dim: usize, net: &crate::math::bernstein::BezierNet) -> Quality {
        let t = [0.0, 0.25, 0.5, 0.75, 1.0];
        let nz = if dim == 2 { 1 } else { 5 };
        let mut q = Samples::new();
        for z in 0..nz {
            for y in 0..5 {
                for x in 0..5 {
                    let u = [t[x], t[y], if dim == 2 { 0.0 } else { t[z] }];
                    let (_, d) = crate::math::bernstein::eval_net_with_derivatives(dim, net, u);
                    q.add(dim, &d);
                }
            }
        }
        q.quality()
    }

    #[test]
    fn sampled_quality_by_sum_factorisation_equals_point_evaluation() {
        for dim in [2, 3] {
            let mut net = [[0.0; 3]; 27];
            for (p, x) in net.iter_mut().enumerate().take(net_len(dim)) {
                let l = [p % 3, (p / 3) % 3, p / 9];
                for k in 0..3 {
                    let wobble = ((p * 7 + k * 3) % 5) as f64 * 0.04;
                    x[k] = if k < dim {
                        l[k] as f64 * 0.5 + wobble
                    } else {
                        0.0
                    };
                }
            }
            let (a, b) = (quality(dim, &net), quality_by_points(dim, &net));
            assert!((a.ratio - b.ratio).abs() < 1e-12, "{dim}D: {a:?} {b:?}");
            assert!((a.scaled - b.scaled).abs() < 1e-12, "{dim}D: {a:?} {b:?}");
            assert!(a.ratio < 0.999 && a.ratio > 0.0, "{dim}D: {a:?}");
        }
    }

    #[test]
    fn graded_affine_maps_have_no_kinks_and_stay_put() {
        let xs = [0.0, 0.1, 0.35, 0.9, 2.0];
        let ys = [0.0, 0.5, 0.75, 1.7];
        let zs = [0.0, 0.2, 0.3, 1.0];
        let mut mesh = grid_3d(&xs, &ys, &zs);
        let a = [[0.8, -0.5, 0.1], [0.55, 0.9, -0.2], [0.05, 0.15, 1.3]];
        for p in &mut mesh.coords {
            let q = *p;
            *p = std::array::from_fn(|i| 1.0 + (0..3).map(|j| a[i][j] * q[j]).sum::<f64>());
        }
        let (topo, space) = all_q2(&mesh);
        let mut c = space.control_points.clone();
        let info = smooth_facet_jumps(
            &space,
            &mesh,
            &topo,
            &|_| false,
            1.0,
            &JumpGuard::default(),
            &mut c,
        )
        .unwrap();
        assert!(info.facets > 0 && info.moved > 0, "{info:?}");
        // The graded cells' derivatives differ in length: only the size-ratio weighting of
        // j makes the affine map's jumps vanish.
        assert!(info.rms_before < 1e-13, "{info:?}");
        let moved = c
            .iter()
            .zip(&space.control_points)
            .map(|(a, b)| norm([a[0] - b[0], a[1] - b[1], a[2] - b[2]]))
            .fold(0.0, f64::max);
        assert!(moved < 1e-13, "an affine map moved by {moved:.2e}");
    }

    /// The angle in degrees between the two elements' transversal derivatives at the
    /// midpoint of every interior facet, from their Bézier nets.
    fn midpoint_angles(space: &SplineSpace, topo: &Topology, c: &[[f64; 3]]) -> Vec<f64> {
        (0..topo.n_facets())
            .filter(|&f| topo.facet_elements[f][1] != NONE)
            .map(|f| {
                let d: Vec<[f64; 3]> = (0..2)
                    .map(|i| {
                        let e = topo.facet_elements[f][i] as usize;
                        let s = usize::from(topo.facet_sides[f][i]);
                        let mut u = [0.5, 0.5, 0.0];
                        u[s / 2] = (s % 2) as f64;
                        let net = space.element_bezier_with(e, c);
                        let (_, j) = eval_net_with_derivatives(2, &net, u);
                        let sign = if s % 2 == 1 { 1.0 } else { -1.0 };
                        j[s / 2].map(|x| sign * x)
                    })
                    .collect();
                let cos = -(d[0][0] * d[1][0] + d[0][1] * d[1][1]) / (norm(d[0]) * norm(d[1]));
                cos.clamp(-1.0, 1.0).acos().to_degrees()
            })
            .collect()
    }

    #[test]
    fn kinks_of_a_q2_grid_are_lowered_and_its_boundary_kept() {
        let u: Vec<f64> = (0..6).map(|i| i as f64).collect();
        let mut mesh = grid_2d(&u, &u);
        let topo0 = Topology::build(&mesh);
        // Interior vertices moved off the grid lines: every interior facet has a kink.
        for (v, p) in mesh.coords.iter_mut().enumerate() {
            if !topo0.vertex_on_boundary[v] {
                p[0] += 0.2 * ((v * 7 % 5) as f64 - 2.0) / 2.0;
                p[1] += 0.2 * ((v * 3 % 5) as f64 - 2.0) / 2.0;
            }
        }
        let (topo, space) = all_q2(&mesh);
        let c0 = space.control_points.clone();
        let mut c = c0.clone();
        let info = smooth_facet_jumps(
            &space,
            &mesh,
            &topo,
            &|_| false,
            1.0,
            &JumpGuard::default(),
            &mut c,
        )
        .unwrap();
        assert!(info.rms_after < 0.5 * info.rms_before, "{info:?}");
        let mean = |a: Vec<f64>| a.iter().sum::<f64>() / a.len() as f64;
        let (before, after) = (
            mean(midpoint_angles(&space, &topo, &c0)),
            mean(midpoint_angles(&space, &topo, &c)),
        );
        assert!(
            after < 0.5 * before,
            "mean kink {before:.2}° -> {after:.2}°"
        );
        // The boundary is the fit's: every Bernstein point on a boundary facet is unchanged.
        for &f in &topo.boundary_facets {
            let (e, s) = (
                topo.facet_elements[f as usize][0] as usize,
                topo.facet_sides[f as usize][0],
            );
            let (a, b) = (
                space.element_bezier_with(e, &c0),
                space.element_bezier_with(e, &c),
            );
            let k = usize::from(s) / 2;
            for p in 0..9 {
                if [p % 3, p / 3][k] == 2 * (usize::from(s) % 2) {
                    assert_eq!(a[p], b[p], "boundary facet {f} moved");
                }
            }
        }
    }
}
