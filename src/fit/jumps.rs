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
//! CG (relative residual 10⁻⁶: a proposal the guard below still judges), gives C = C* + δ
//! on the movable points. J is applied in factors (`Jumps`): each element's outward
//! differences between its facet layer and the next at the facet's Bernstein positions (sparse
//! over control points, two per Bernstein point of a Q2 element), then the facet's 3^(d−1) ×
//! 3^(d−1) Bernstein values at the points, weighted; never as J's rows over both elements'
//! points, which cost a full CSR of 9 × 54 entries per 3D facet.
//!
//! **Only the C⁰ facets' neighbourhood is evaluated.** A move reaches the elements of J's
//! points (`near`), and an element's risk freezes points only through elements sharing a point
//! with it (`around`, one more ring): the fitted quality is sampled there alone, the halvings
//! re-sample only the elements of the points just halved, and every other element keeps the
//! fit's control points without being looked at. Only the straight mesh's smallest values and
//! 1st percentiles (the blend's, by definition over every element) and the supports (one
//! element's control points: its Kronecker factors' non-zero columns, read without expanding
//! its rows) cover the whole mesh.
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
    /// Elements within the margin of the blend's rules at the fit, or outside them, among
    /// those sharing a control point with an element a move can reach (no other is
    /// evaluated): their points and their neighbours' stay at the fit.
    pub at_risk_elements: usize,
    /// Elements a move took below their needs (the moves of their points then halved),
    /// counted once per halving.
    pub frozen_elements: usize,
    /// Wall time of the smoothing, set by the caller (0 when it is not).
    pub seconds: f64,
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
    let jumps = Jumps::new(space, mesh, topo, &facets, c);
    let j0 = jumps.of(&jumps.diff.times(c));
    let mut info = JumpInfo {
        facets: facets.len(),
        rms_before: jumps.rms(&j0),
        rms_after: jumps.rms(&j0),
        ..Default::default()
    };
    if jumps.points() == 0 {
        return Ok(info);
    }
    let dim = topo.dim;
    let start = c.to_vec();
    // The region: the points in J's rows, the elements they shape (`near`, the only ones a
    // move can reach) and the elements sharing a point with those (`around`, the only ones
    // whose risk can freeze a point of J's rows). Nothing beyond is evaluated.
    let supports = Supports::new(space);
    let mut in_rows = vec![false; c.len()];
    jumps
        .diff
        .cols
        .iter()
        .for_each(|&id| in_rows[id as usize] = true);
    let rows_points: Vec<usize> = (0..c.len()).filter(|&i| in_rows[i]).collect();
    let near = supports.elements_of(rows_points.iter().copied());
    let around = supports.elements_of(
        near.iter()
            .flat_map(|&e| supports.element(e).iter().map(|&id| id as usize)),
    );
    let needs = Needs::new(space, mesh, guard, &start, &around);
    let mut frozen = boundary_points(space, topo, &near, c.len());
    // Elements at risk at the fit (outside the rules, or within MARGIN of them) are held back,
    // or may be: their points and those of every element sharing one stay at the fit, so
    // the blend's reduction of them meets neighbours as the fit left them.
    for &e in around.iter().filter(|&&e| needs.at_risk[e]) {
        info.at_risk_elements += 1;
        for &id in supports.element(e) {
            for &n in supports.of(id as usize) {
                for &q in supports.element(n as usize) {
                    frozen[q as usize] = true;
                }
            }
        }
    }
    let (movable, delta, iterations) = solve(&jumps, &rows_points, &j0, &frozen, weight)?;
    info.iterations = iterations;
    // The move of each movable point, halved for every element it takes below its needs
    // ([`HALVINGS`] times, then dropped), until no element is.
    let mut slot = vec![u32::MAX; c.len()];
    for (i, &id) in movable.iter().enumerate() {
        slot[id] = i as u32;
    }
    let mut halved = vec![0u32; movable.len()];
    let mut touched = supports.elements_of(movable.iter().copied());
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
        let poorer = needs.poorer(space, dim, &touched, c);
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
        for &id in &points {
            halved[slot[id as usize] as usize] += 1;
        }
        // Only the elements of the points just halved change.
        touched = supports.elements_of(points.iter().map(|&id| id as usize));
    }
    info.moved = movable.iter().filter(|&&i| c[i] != start[i]).count();
    info.rms_after = jumps.rms(&jumps.of(&jumps.diff.times(c)));
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
    fn new(
        space: &dyn FitSpace,
        mesh: &LinearMesh,
        guard: &JumpGuard,
        fit: &[[f64; 3]],
        region: &[usize],
    ) -> Self {
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
        let per: Vec<(f64, f64, bool)> = region
            .par_iter()
            .map(|&e| {
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
        let mut needs = Needs {
            ratio: vec![f64::NAN; n],
            scaled: vec![f64::NAN; n],
            at_risk: vec![false; n],
        };
        for (&e, p) in region.iter().zip(per) {
            (needs.ratio[e], needs.scaled[e], needs.at_risk[e]) = p;
        }
        needs
    }

    /// The elements of `elements` (each inside the region of [`Needs::new`]) that `c` takes
    /// below their needs.
    fn poorer(
        &self,
        space: &dyn FitSpace,
        dim: usize,
        elements: &[usize],
        c: &[[f64; 3]],
    ) -> Vec<usize> {
        elements
            .par_iter()
            .copied()
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
                    // A Kronecker product times distinct nodes: a node is in a row where its
                    // three 1D columns are non-zero.
                    if let Some(m) = space.element_factors(e, cols) {
                        let used = |k: usize, j: usize| m[k].iter().any(|row| row[j] != 0.0);
                        let mut ids: Vec<u32> = cols
                            .iter()
                            .enumerate()
                            .filter(|&(l, _)| {
                                used(0, l % 3) && used(1, (l / 3) % 3) && used(2, l / 9)
                            })
                            .map(|(_, &id)| id)
                            .collect();
                        ids.sort_unstable();
                        return ids;
                    }
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

    /// The elements of the control points `ids`, sorted and distinct.
    fn elements_of(&self, ids: impl Iterator<Item = usize>) -> Vec<usize> {
        let mut seen = vec![false; self.element.rows()];
        for id in ids {
            for &e in self.of(id) {
                seen[e as usize] = true;
            }
        }
        (0..seen.len()).filter(|&e| seen[e]).collect()
    }
}

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

    /// A x.
    fn times(&self, x: &[[f64; 3]]) -> Vec<[f64; 3]> {
        let mut y = vec![[0.0; 3]; self.rows()];
        self.mul(x, &mut y);
        y
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

/// J in factors. At each of a facet's m = 3^(d−1) points p (numbered by their grid indices
/// in the facet's directions of its first element a), each element x of the facet has the
/// outward transversal derivative d_x(p) = Σ_β B(π_x(p), β) D_xβ: D_xβ = 2 (net_x(β on the
/// facet) − net_x(β one layer in)) over the facet's m Bernstein positions β of x, B the
/// quadratic Bernstein values at ¼, ½, ¾ (tensor products in 3D) and π_x(p) the point's grid
/// index in x (the identity for a). Then j(p) = w_a(p) d_a(p) + w_b(p) d_b(p), w_a = ℓ_b /
/// (ℓ_a + ℓ_b) at the fit. J is applied as the sparse differences D (two control points per
/// Bernstein point of a Q2 element), then m × m per element and facet: a facet's 2m rows
/// of D, not J's m rows over both elements' 2 × 27 points.
struct Jumps {
    /// Points (and Bernstein positions) per facet.
    m: usize,
    /// B(p, β), row-major m × m.
    basis: Vec<f64>,
    /// The differences D: 2m rows per facet, a's m then b's m.
    diff: Csr,
    /// π_b: per facet, each point's grid index in b.
    perm: Vec<[u8; 9]>,
    /// w_a(p) then w_b(p), 2m per facet; 0 at a point where an ℓ vanishes (no row).
    weights: Vec<f64>,
}

impl Jumps {
    /// The C⁰ `facets`' factors, ℓ at `c` (a facet whose vertices are not corners of both
    /// elements has no points).
    fn new(
        space: &dyn FitSpace,
        mesh: &LinearMesh,
        topo: &Topology,
        facets: &[usize],
        c: &[[f64; 3]],
    ) -> Self {
        let dim = topo.dim;
        let m = if dim == 2 { 3 } else { 9 };
        let b1 = AT.map(bernstein2);
        let basis: Vec<f64> = (0..m * m)
            .map(|i| {
                let (p, beta) = (i / m, i % m);
                if dim == 2 {
                    b1[p][beta]
                } else {
                    b1[p % 3][beta % 3] * b1[p / 3][beta / 3]
                }
            })
            .collect();
        // Each element's extraction rows once (an element has up to 2d C⁰ facets).
        let mut at = vec![u32::MAX; space.n_elements()];
        let mut elements: Vec<usize> = facets
            .iter()
            .flat_map(|&f| topo.facet_elements[f].map(|e| e as usize))
            .collect();
        elements.sort_unstable();
        elements.dedup();
        for (i, &e) in elements.iter().enumerate() {
            at[e] = i as u32;
        }
        let rows: Vec<ExtractionRows> = elements
            .par_iter()
            .map(|&e| {
                let mut r = ExtractionRows::default();
                space.element_rows(e, &mut r.offsets, &mut r.cols, &mut r.weights);
                r
            })
            .collect();
        let rows_of = |e: usize| &rows[at[e] as usize];
        let per: Vec<Option<FacetDiff>> = facets
            .par_iter()
            .map(|&f| facet_diff(mesh, topo, f, &rows_of))
            .collect();
        let mut diff = Csr::default();
        let mut perm = Vec::new();
        for d in per.into_iter().flatten() {
            for &len in &d.lens[..2 * m] {
                diff.offsets
                    .push(diff.offsets.last().unwrap() + len as usize);
            }
            diff.cols.extend(d.cols);
            diff.vals.extend(d.vals);
            perm.push(d.perm);
        }
        let mut jumps = Jumps {
            m,
            basis,
            diff,
            perm,
            weights: Vec::new(),
        };
        // ℓ at the fit.
        let d = jumps.diff.times(c);
        jumps.weights = (0..jumps.perm.len())
            .into_par_iter()
            .flat_map_iter(|f| {
                let (ya, yb) = jumps.sides(f, &d);
                let mut w = vec![0.0; 2 * m];
                for p in 0..m {
                    let (la, lb) = (norm(ya[p]), norm(yb[p]));
                    if la > 0.0 && lb > 0.0 {
                        w[p] = lb / (la + lb);
                        w[m + p] = la / (la + lb);
                    }
                }
                w
            })
            .collect();
        jumps
    }

    /// The facets' points with a row (both ℓ positive).
    fn points(&self) -> usize {
        (0..self.weights.len() / 2)
            .filter(|&i| self.weights[2 * (i / self.m) * self.m + i % self.m] > 0.0)
            .count()
    }

    /// d_a(p) and d_b(p) of facet `f` from the differences `d` (D applied to the points).
    fn sides(&self, f: usize, d: &[[f64; 3]]) -> ([[f64; 3]; 9], [[f64; 3]; 9]) {
        let m = self.m;
        let (da, db) = (
            &d[2 * m * f..2 * m * f + m],
            &d[2 * m * f + m..2 * m * (f + 1)],
        );
        let (mut ya, mut yb) = ([[0.0; 3]; 9], [[0.0; 3]; 9]);
        for p in 0..m {
            let (ra, rb) = (
                &self.basis[p * m..(p + 1) * m],
                &self.basis[self.perm[f][p] as usize * m..(self.perm[f][p] as usize + 1) * m],
            );
            for beta in 0..m {
                for k in 0..3 {
                    ya[p][k] += ra[beta] * da[beta][k];
                    yb[p][k] += rb[beta] * db[beta][k];
                }
            }
        }
        (ya, yb)
    }

    /// j at every facet point (m per facet) from the differences `d`.
    fn of(&self, d: &[[f64; 3]]) -> Vec<[f64; 3]> {
        let m = self.m;
        let mut j = vec![[0.0; 3]; m * self.perm.len()];
        j.par_chunks_mut(m).enumerate().for_each(|(f, j)| {
            let (ya, yb) = self.sides(f, d);
            let w = &self.weights[2 * m * f..2 * m * (f + 1)];
            for p in 0..m {
                for k in 0..3 {
                    j[p][k] = w[p] * ya[p][k] + w[m + p] * yb[p][k];
                }
            }
        });
        j
    }

    /// Jᵀ's step before Dᵀ: per facet the 2m vectors Bᵀ (w_a r) and Bᵀ π_b (w_b r), `r` one
    /// vector per facet point.
    fn back(&self, r: &[[f64; 3]]) -> Vec<[f64; 3]> {
        let m = self.m;
        let mut g = vec![[0.0; 3]; 2 * m * self.perm.len()];
        g.par_chunks_mut(2 * m).enumerate().for_each(|(f, g)| {
            let w = &self.weights[2 * m * f..2 * m * (f + 1)];
            for p in 0..m {
                let rp = r[m * f + p];
                let pb = self.perm[f][p] as usize;
                for beta in 0..m {
                    let (ba, bb) = (
                        w[p] * self.basis[p * m + beta],
                        w[m + p] * self.basis[pb * m + beta],
                    );
                    for k in 0..3 {
                        g[beta][k] += ba * rp[k];
                        g[m + beta][k] += bb * rp[k];
                    }
                }
            }
        });
        g
    }

    /// Root mean square of the j at the points with a row.
    fn rms(&self, j: &[[f64; 3]]) -> f64 {
        let s: f64 = j.iter().map(|v| v.iter().map(|x| x * x).sum::<f64>()).sum();
        (s / self.points().max(1) as f64).sqrt()
    }
}

/// An element's extraction rows ([`FitSpace::element_rows`]).
#[derive(Default)]
struct ExtractionRows {
    offsets: Vec<usize>,
    cols: Vec<u32>,
    weights: Vec<f64>,
}

/// One facet's rows of D and its points' grid indices in b ([`Jumps`]).
struct FacetDiff {
    lens: [u16; 18],
    cols: Vec<u32>,
    vals: Vec<f64>,
    perm: [u8; 9],
}

/// The grid index, in element `e`'s facet directions (those other than `k`), of each facet
/// point: (s, t) ∈ {¼, ½, ¾}^(d−1) placed by its bilinear (2D: linear) weights over the
/// facet's vertices, whose reference corners in `e` are `r` (None unless every point lands
/// on that grid, once).
fn grid_in(dim: usize, r: &[[f64; 3]], k: usize) -> Option<[u8; 9]> {
    let axes: Vec<usize> = (0..dim).filter(|&a| a != k).collect();
    let phis: Vec<Vec<f64>> = if dim == 2 {
        AT.iter().map(|&t| vec![1.0 - t, t]).collect()
    } else {
        AT.iter()
            .flat_map(|&s| {
                AT.iter()
                    .map(move |&t| vec![(1.0 - s) * (1.0 - t), s * (1.0 - t), s * t, (1.0 - s) * t])
            })
            .collect()
    };
    let mut out = [0u8; 9];
    let mut seen = [false; 9];
    for (q, phi) in phis.iter().enumerate() {
        let mut index = 0usize;
        for (n, &a) in axes.iter().enumerate() {
            let u: f64 = phi.iter().zip(r).map(|(w, x)| w * x[a]).sum();
            let g = (4.0 * u).round() - 1.0;
            if !(0.0..=2.0).contains(&g) || (4.0 * u - (g + 1.0)).abs() > 1e-9 {
                return None;
            }
            index += g as usize * if n == 0 { 1 } else { 3 };
        }
        if seen[index] {
            return None;
        }
        seen[index] = true;
        out[q] = index as u8;
    }
    Some(out)
}

/// Facet `f`'s rows of D ([`Jumps`]): per element x of the facet and Bernstein position β of
/// the facet in x (numbered by x's grid of the facet's directions), 2 (net_x(β on the facet)
/// − net_x(β one layer in)) over control points. None when a vertex of the facet is not a
/// corner of both elements.
fn facet_diff<'r>(
    mesh: &LinearMesh,
    topo: &Topology,
    f: usize,
    rows_of: &dyn Fn(usize) -> &'r ExtractionRows,
) -> Option<FacetDiff> {
    let dim = topo.dim;
    let m = if dim == 2 { 3 } else { 9 };
    let elements = topo.facet_elements[f].map(|e| e as usize);
    let sides = topo.facet_sides[f].map(usize::from);
    let local: &[usize] = if dim == 2 {
        &QUAD_SIDES[sides[0]]
    } else {
        &HEX_SIDES[sides[0]]
    };
    let vertices: Vec<u32> = local
        .iter()
        .map(|&i| mesh.element(elements[0])[i])
        .collect();
    let grids = [0, 1].map(|x| {
        let r = corners_in(mesh, elements[x], &vertices)?;
        grid_in(dim, &r, sides[x] / 2)
    });
    let [Some(ga), Some(gb)] = grids else {
        return None;
    };
    // Points numbered by a's grid: π_b(ga[q]) = gb[q].
    let mut perm = [0u8; 9];
    for q in 0..m {
        perm[ga[q] as usize] = gb[q];
    }
    let mut out = FacetDiff {
        lens: [0; 18],
        cols: Vec::new(),
        vals: Vec::new(),
        perm,
    };
    let mut entries: Vec<(u32, f64)> = Vec::new();
    for x in 0..2 {
        let (e, s) = (elements[x], sides[x]);
        let ExtractionRows {
            offsets,
            cols,
            weights,
        } = rows_of(e);
        let k = s / 2;
        let axes: Vec<usize> = (0..dim).filter(|&a| a != k).collect();
        for beta in 0..m {
            let mut l = [0usize; 3];
            l[axes[0]] = beta % 3;
            if dim == 3 {
                l[axes[1]] = beta / 3;
            }
            let at = |layer: usize| {
                let mut l = l;
                l[k] = layer;
                l[0] + 3 * l[1] + 9 * l[2]
            };
            entries.clear();
            for (bernstein, factor) in [(at(2 * (s % 2)), 2.0), (at(1), -2.0)] {
                for q in offsets[bernstein]..offsets[bernstein + 1] {
                    entries.push((cols[q], factor * weights[q]));
                }
            }
            entries.sort_unstable_by_key(|p| p.0);
            let before = out.cols.len();
            for &(id, v) in &entries {
                if out.cols.len() > before && out.cols.last() == Some(&id) {
                    *out.vals.last_mut().unwrap() += v;
                } else {
                    out.cols.push(id);
                    out.vals.push(v);
                }
            }
            out.lens[x * m + beta] = (out.cols.len() - before) as u16;
        }
    }
    Some(out)
}

/// I + W JᵀJ on the movable points: J = [`Jumps`], its columns of the movable points.
struct Smoothing<'a> {
    jumps: &'a Jumps,
    /// Dᵀ over all control points.
    diff_t: Csr,
    movable: &'a [usize],
    weight: f64,
}

impl Smoothing<'_> {
    /// Dᵀ g at the movable points.
    fn back_to_movable(&self, g: &[[f64; 3]]) -> Vec<[f64; 3]> {
        let t = &self.diff_t;
        self.movable
            .par_iter()
            .map(|&id| {
                let mut s = [0.0; 3];
                for q in t.offsets[id]..t.offsets[id + 1] {
                    let (r, v) = (t.cols[q] as usize, t.vals[q]);
                    for d in 0..3 {
                        s[d] += v * g[r][d];
                    }
                }
                s
            })
            .collect()
    }
}

impl crate::solve::LinOp for Smoothing<'_> {
    fn nrows(&self) -> usize {
        self.movable.len()
    }

    fn apply(&self, x: &[[f64; 3]], y: &mut [[f64; 3]]) {
        let mut all = vec![[0.0; 3]; self.diff_t.rows()];
        for (&id, x) in self.movable.iter().zip(x) {
            all[id] = *x;
        }
        let j = self.jumps.of(&self.jumps.diff.times(&all));
        y.copy_from_slice(&self.back_to_movable(&self.jumps.back(&j)));
        y.par_iter_mut().zip(x).for_each(|(y, x)| {
            for d in 0..3 {
                y[d] = x[d] + self.weight * y[d];
            }
        });
    }

    /// 1 + W Σ_p J_pi² per point i: J's column of i, facet by facet.
    fn diagonal(&self) -> Vec<f64> {
        let (m, jumps) = (self.jumps.m, self.jumps);
        let parts: Vec<Vec<(u32, f64)>> = (0..jumps.perm.len())
            .into_par_iter()
            .map(|f| {
                let rows = 2 * m * f..2 * m * (f + 1);
                let mut entries: Vec<(u32, usize, f64)> = rows
                    .flat_map(|r| {
                        let d = &jumps.diff;
                        (d.offsets[r]..d.offsets[r + 1])
                            .map(move |q| (d.cols[q], r - 2 * m * f, d.vals[q]))
                    })
                    .collect();
                entries.sort_unstable_by_key(|e| e.0);
                let w = &jumps.weights[2 * m * f..2 * m * (f + 1)];
                let mut out = Vec::new();
                for group in entries.chunk_by(|a, b| a.0 == b.0) {
                    let mut column = [0.0; 9];
                    for &(_, row, v) in group {
                        let (x, beta) = (row / m, row % m);
                        for (p, cp) in column.iter_mut().enumerate().take(m) {
                            let pp = if x == 0 { p } else { jumps.perm[f][p] as usize };
                            *cp += w[x * m + p] * jumps.basis[pp * m + beta] * v;
                        }
                    }
                    out.push((group[0].0, column.iter().map(|v| v * v).sum::<f64>()));
                }
                out
            })
            .collect();
        let mut all = vec![0.0; self.diff_t.rows()];
        for (i, s) in parts.into_iter().flatten() {
            all[i as usize] += s;
        }
        self.movable
            .iter()
            .map(|&id| 1.0 + self.weight * all[id])
            .collect()
    }
}

/// The minimiser's move δ of the points of `in_rows` (J's points) that are not `frozen`:
/// (I + W JᵀJ) δ = −W Jᵀ J C* over them, with J C* = `j0`. Returns the points, their moves
/// and the CG's iterations.
fn solve(
    jumps: &Jumps,
    in_rows: &[usize],
    j0: &[[f64; 3]],
    frozen: &[bool],
    weight: f64,
) -> Result<Move, CgError> {
    // Movable control points, numbered in id order.
    let movable: Vec<usize> = in_rows.iter().copied().filter(|&i| !frozen[i]).collect();
    if movable.is_empty() {
        return Ok((movable, Vec::new(), 0));
    }
    // D over all control points, the frozen ones held at 0, and its transpose's movable rows.
    let op = Smoothing {
        jumps,
        diff_t: jumps.diff.transpose(frozen.len()),
        movable: &movable,
        weight,
    };
    let mut b = op.back_to_movable(&jumps.back(j0));
    b.iter_mut().flatten().for_each(|v| *v *= -weight);
    let mut delta = vec![[0.0; 3]; movable.len()];
    let params = CgParams {
        rel_tol: 1e-6,
        preconditioner: crate::solve::CgPreconditioner::Jacobi,
        ..CgParams::default()
    };
    let cg = crate::solve::pcg(&op, &b, &mut delta, &params, |_, _| {})?;
    Ok((movable, delta, cg.iterations))
}

/// The movable points, their moves and the CG's iterations ([`solve`]).
type Move = (Vec<usize>, Vec<[f64; 3]>, usize);

/// Control points with a non-zero weight at a Bernstein point of a boundary facet of one of
/// `elements`.
fn boundary_points(
    space: &dyn FitSpace,
    topo: &Topology,
    elements: &[usize],
    n: usize,
) -> Vec<bool> {
    let dim = topo.dim;
    let nb = net_len(dim);
    let (mut offsets, mut cols, mut weights) = (Vec::new(), Vec::new(), Vec::new());
    let mut frozen = vec![false; n];
    for &e in elements {
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

fn norm(v: [f64; 3]) -> f64 {
    (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt()
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

    /// An n × n grid of unit squares whose interior vertices are moved by up to `amplitude`.
    fn wobbled_grid(n: usize, amplitude: f64) -> LinearMesh {
        let u: Vec<f64> = (0..=n).map(|i| i as f64).collect();
        let mut mesh = grid_2d(&u, &u);
        let topo = Topology::build(&mesh);
        for (v, p) in mesh.coords.iter_mut().enumerate() {
            if !topo.vertex_on_boundary[v] {
                p[0] += amplitude * ((v * 7 % 5) as f64 - 2.0) / 2.0;
                p[1] += amplitude * ((v * 3 % 5) as f64 - 2.0) / 2.0;
            }
        }
        mesh
    }

    #[test]
    fn kinks_of_a_q2_grid_are_lowered_and_its_boundary_kept() {
        // Interior vertices moved off the grid lines: every interior facet has a kink.
        let mesh = wobbled_grid(5, 0.2);
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

    /// The distinct control points with a non-zero weight in element `e`'s net.
    fn points_of(space: &SplineSpace, e: usize) -> Vec<usize> {
        let (mut offsets, mut cols, mut weights) = (Vec::new(), Vec::new(), Vec::new());
        FitSpace::element_rows(space, e, &mut offsets, &mut cols, &mut weights);
        let mut ids: Vec<usize> = cols
            .iter()
            .zip(&weights)
            .filter(|p| *p.1 != 0.0)
            .map(|p| *p.0 as usize)
            .collect();
        ids.sort_unstable();
        ids.dedup();
        ids
    }

    #[test]
    fn only_the_c0_facets_neighbourhood_moves_and_risk_two_rings_out_still_freezes() {
        // A wobbled 12 × 12 spline grid with one Q2 element in the middle: its four facets
        // are the only C⁰ facets.
        let mesh = wobbled_grid(12, 0.15);
        let topo = Topology::build(&mesh);
        let centre = |e: usize| -> [f64; 2] {
            let x = mesh.element_coords(e);
            std::array::from_fn(|k| x[..4].iter().map(|p| p[k]).sum::<f64>() / 4.0)
        };
        let middle = (0..mesh.n_elements())
            .min_by(|&a, &b| {
                let d = |e: usize| (centre(e)[0] - 6.0).powi(2) + (centre(e)[1] - 6.0).powi(2);
                d(a).total_cmp(&d(b))
            })
            .unwrap();
        let mut demote = vec![false; mesh.n_elements()];
        demote[middle] = true;
        let space = SplineSpace::build_with_demoted(&mesh, &topo, &demote);
        let n = mesh.n_elements();
        let points: Vec<Vec<usize>> = (0..n).map(|e| points_of(&space, e)).collect();
        let mut elements_of = vec![Vec::new(); space.control_points.len()];
        for (e, ids) in points.iter().enumerate() {
            ids.iter().for_each(|&id| elements_of[id].push(e));
        }
        let c0_elements: Vec<usize> = (0..topo.n_facets())
            .filter(|&f| {
                let [a, b] = topo.facet_elements[f];
                b != NONE && !(space.is_spline(a as usize) && space.is_spline(b as usize))
            })
            .flat_map(|f| topo.facet_elements[f].map(|e| e as usize))
            .collect();
        let mut near_c0 = vec![false; space.control_points.len()];
        c0_elements
            .iter()
            .for_each(|&e| points[e].iter().for_each(|&id| near_c0[id] = true));
        let run = |c: &mut Vec<[f64; 3]>| {
            smooth_facet_jumps(
                &space,
                &mesh,
                &topo,
                &|e| space.is_spline(e),
                1.0,
                &JumpGuard::default(),
                c,
            )
            .unwrap()
        };
        let fit = space.control_points.clone();
        let mut c = fit.clone();
        let info = run(&mut c);
        let moved: Vec<usize> = (0..c.len()).filter(|&i| c[i] != fit[i]).collect();
        assert!(!moved.is_empty(), "{info:?}");
        // Only points of the C⁰ facets' elements move: every element sharing no point with
        // them keeps the fit's net exactly.
        for e in 0..n {
            if points[e].iter().all(|&id| !near_c0[id]) {
                assert_eq!(
                    space.element_bezier_with(e, &c),
                    space.element_bezier_with(e, &fit),
                    "element {e}, far from the C⁰ facets, moved"
                );
            }
        }
        // A point q whose elements have no point of a C⁰ facet's element (nor any point of
        // J's rows: they are outside the elements a move reaches) but share a point with an
        // element that moved.
        let shaped = |id: usize| {
            elements_of[id]
                .iter()
                .flat_map(|&e| points[e].iter().copied())
        };
        let moved_elements: Vec<bool> = (0..n)
            .map(|e| points[e].iter().any(|id| moved.contains(id)))
            .collect();
        let q = (0..c.len())
            .find(|&id| {
                elements_of[id]
                    .iter()
                    .all(|&e| points[e].iter().all(|&p| !near_c0[p]))
                    && shaped(id).any(|p| elements_of[p].iter().any(|&e| moved_elements[e]))
            })
            .expect("a point two rings out");
        // The fit bent there: by the rule over the whole mesh, every point of every element
        // sharing a point with an element at risk keeps the fit's position.
        let mut bent = fit.clone();
        bent[q][0] += 0.9;
        let mut c = bent.clone();
        let info = run(&mut c);
        let all: Vec<usize> = (0..n).collect();
        let needs = Needs::new(&space, &mesh, &JumpGuard::default(), &bent, &all);
        let frozen_by = |e: usize| -> Vec<usize> {
            points[e]
                .iter()
                .flat_map(|&p| {
                    elements_of[p]
                        .iter()
                        .flat_map(|&m| points[m].iter().copied())
                })
                .collect()
        };
        let risk: Vec<usize> = (0..n).filter(|&e| needs.at_risk[e]).collect();
        assert!(
            risk.iter().any(|&e| {
                points[e].iter().all(|&p| !near_c0[p])
                    && frozen_by(e).iter().any(|id| moved.contains(id))
            }),
            "no element at risk two rings out: {risk:?}"
        );
        assert!(info.moved > 0, "{info:?}");
        for &e in &risk {
            for id in frozen_by(e) {
                assert_eq!(
                    c[id], bent[id],
                    "point {id} beside element {e} at risk moved"
                );
            }
        }
    }
}
