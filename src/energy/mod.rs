//! Element degeneration energy (paper §2.4): the least-squares objective plus a symmetric
//! Dirichlet energy of every element, minimised under the det J certificate.
//!
//! **Inputs:** a spline space ([`FitSpace`]), the linear mesh it was built from, the
//! least-squares fit's parameters and solution C*, [`EnergyParams`], a start C that is certified
//! valid (the least-squares result after its line search), and a [`Certifier`].
//! **Output:** control points C with Q(C) ≤ Q(start), every element certified valid, the
//! boundary unchanged, and an [`EnergyInfo`].
//!
//! **The boundary is the fit's.** The degeneration energy knows nothing of the surface the
//! boundary approximates: left free, it trades the boundary's accuracy (tens of times the
//! fit's distance from the true surface) for a slightly better Jacobian. The control points
//! that carry the boundary (a non-zero extraction weight at a Bernstein point of a boundary
//! facet) are therefore kept where the least-squares fit put them (zero gradient for L-BFGS,
//! no local problem for the coloured solver); only interior control points move, so the
//! boundary of the result is the fit's exactly.
//!
//! **Energy.** Q(C) = (D + R)(C) − (D + R)(C*) + w_e Σ_e S_e(C), where D + R is the fit's
//! quadratic (normal equations K, F of [`crate::fit`]; written relative to its unconstrained
//! minimum, so the first term is (δ − δ*)ᵀ K (δ − δ*) ≥ 0) and
//!
//! S_e = h_e² Σ_q w_q f(M_q),   f(M) = (‖M‖²_F + ‖M⁻¹‖²_F) / (2d) − 1,   M_q = J_e(u_q) J⁰_e(u_q)⁻¹,
//!
//! with J_e the Jacobian of the curved element's map, J⁰_e that of the straight input element at
//! the same reference point, u_q, w_q a 3^d Gauss rule on \[0,1\]^d (weights summing to 1), and
//! h_e² a length² ([`EnergyScale`]: the mean input element volume^{2/d} for every element by
//! default, or each element's own). f is the standard symmetric Dirichlet energy (the paper's
//! eq. 11 is garbled) normalised so that its minimum, 0, is attained exactly when M is a
//! rotation; f is invariant to scaling the mesh, so thin boundary-layer cells that keep their
//! input shape cost nothing, and h_e² gives S_e the units of D (length²), so the weight w_e is
//! dimensionless and Q scales with the mesh. f = +∞ where det M ≤ 0 at a quadrature point
//! (the barrier); the minimisers additionally accept a step only when every element it touches
//! stays certified valid by the Bernstein bound.
//!
//! **Gradient.** With the element's Bernstein net B = R_e C (extraction rows), J = Σ_a B_a ⊗ ∇b_a
//! and M = J P (P = J⁰⁻¹): ∂f/∂M = (M − M⁻ᵀ M⁻¹ M⁻ᵀ)/d and ∂S/∂B_a = h² Σ_q w_q (∂f/∂M) Pᵀ ∇b_a,
//! then ∂/∂C = R_eᵀ ∂/∂B. The least-squares term contributes 2(K δ − (F − K C0)).
//!
//! **Solvers.** [`EnergySolver::Lbfgs`]: L-BFGS with Armijo backtracking, a step accepted only
//! when every element is certified. [`EnergySolver::Colored`] ([`colored`]): control points are
//! coloured so that no two of one colour share an element; each colour is optimised in parallel
//! by Newton steps on each control point's local energy with a certified line search on its
//! support elements, colour after colour, until a sweep stalls (with a GPU, the first Newton
//! step's derivatives come from `shaders/local_newton.wgsl`).
//!
//! **Rotation seams.** Where the space sees control points rotated across a periodic seam
//! ([`FitSpace::frames`]: element e takes R C for such a point), the element's net applies R to
//! those points (`Energy::net`), their gradient shares take Rᵀ, and the least-squares term is
//! the coupled fit's, (δ − δ*)ᵀ (K ⊗ I₃ + C) (δ − δ*) ([`crate::fit::rotated`]), so C* is still
//! its minimum. The coloured solver's local problem for such a point is that of Rᵀ M (f and
//! det are invariant under a rotation on the left, and M + (R v) ψᵀ = R (Rᵀ M + v ψᵀ)) plus
//! the coupling's row in its linear term: the local kernels (CPU and GPU) are unchanged.
//!
//! **Determinism.** Element contributions are computed in parallel into per-element slots and
//! summed in element order, so values and iterates do not depend on the thread count.

pub mod colored;
mod lbfgs;
mod params;

use crate::math::BezierNet;
pub use colored::{CpuEnergyKernel, EnergyKernel, KernelError};
pub use params::{EnergyError, EnergyInfo, EnergyParams, EnergyScale, EnergySolver, EnergyStop};

use crate::fit::{FitParams, FitSpace, NormalMatrix};
use crate::math::bernstein::net_len;
use crate::math::bernstein::{bernstein2, bernstein2_derivative, elevated_net};
pub use crate::math::linalg::Mat3;
use crate::math::linalg::{DMat3, DVec3, inverse, norm2_rows};
use crate::math::quadrature::GAUSS3;
use crate::mesh::{LinearMesh, Topology};
use crate::solve::LinOp;
use crate::validity::Certifier;
use rayon::prelude::*;
use std::time::Instant;

/// Symmetric Dirichlet density f(M) (M embedded as 3×3 with M₃₃ = 1 in 2D, which the `−6`
/// accounts for) and, when `grad` is given, ∂f/∂M. +∞ when det M ≤ 0.
pub fn dirichlet(dim: usize, m: &DMat3, grad: Option<&mut DMat3>) -> f64 {
    let (a, det) = inverse(m);
    if !(det > 0.0) {
        return f64::INFINITY;
    }
    let d = dim as f64;
    let f = (norm2_rows(m) + norm2_rows(&a) - 6.0) / (2.0 * d);
    if let Some(g) = grad {
        // ∂‖M⁻¹‖²/∂M = −2 M⁻ᵀ M⁻¹ M⁻ᵀ.
        let at = a.transpose();
        let t = at * a * at;
        *g = (*m - t) / d;
    }
    f
}

/// One element's extraction as a dense matrix on its distinct control points.
pub(crate) struct ElementRows {
    /// Distinct control points, sorted.
    pub ids: Vec<u32>,
    /// nb × ids.len(), row-major: Bernstein point a = Σ_k r[a·m + k] C[ids[k]].
    pub r: Vec<f64>,
}

/// The energy Q with its per-element reference data precomputed.
pub struct Energy<'a> {
    pub(crate) space: &'a dyn FitSpace,
    pub(crate) dim: usize,
    pub(crate) nb: usize,
    pub(crate) weight: f64,
    pub(crate) k: NormalMatrix,
    /// F − K C0 (the displacement right-hand side).
    pub(crate) rhs: Vec<[f64; 3]>,
    /// δ*ᵀ (F − K C0), the constant making the least-squares term vanish at C*.
    ls_offset: f64,
    /// Quadrature weights and reference gradients ∇b_a(u_q) (component, Bernstein index).
    pub(crate) qw: Vec<f64>,
    pub(crate) dbq: Vec<[[f64; 27]; 3]>,
    /// Per element and quadrature point: P = J⁰⁻¹ (flattened element-major).
    pub(crate) pinv: Vec<DMat3>,
    /// Per element: w_e h_e².
    pub(crate) scale: Vec<f64>,
    pub(crate) rows: Vec<ElementRows>,
    /// Per element: the constant part of its net (periodic seam offsets), if any.
    shifts: Vec<Option<Box<BezierNet>>>,
    /// Per element: the control points it sees rotated across a rotation seam, as (column in
    /// its rows, R): its net takes R C for them ([`FitSpace::frames`]); empty for most.
    pub(crate) rotated: Vec<Vec<(u32, Mat3)>>,
    /// The least-squares coupling across rotation seams ([`crate::fit::rotated`]): the fit's
    /// matrix is K ⊗ I₃ + C there; `None` without rotation seams.
    pub(crate) coupling: Option<crate::fit::rotated::Coupling>,
    /// Smallest input element size vol^{1/d}.
    pub(crate) h_min: f64,
    /// Control points that carry the boundary (a non-zero extraction weight at a Bernstein
    /// point of a boundary facet); the minimisers keep them where the least-squares fit put
    /// them, so the boundary stays the fit's (see the module docs).
    pub(crate) frozen: Vec<bool>,
}

impl<'a> Energy<'a> {
    /// Precompute the reference data; `c_star` is the least-squares solution.
    pub fn new(
        space: &'a dyn FitSpace,
        mesh: &LinearMesh,
        topo: &Topology,
        fit: &FitParams,
        c_star: &[[f64; 3]],
        params: &EnergyParams,
    ) -> Result<Self, EnergyError> {
        let smooth = crate::fit::smooth_targets(mesh, topo, fit);
        Self::with_targets(space, mesh, topo, fit, smooth.as_ref(), c_star, params)
    }

    /// [`Energy::new`] with the fit's smooth targets `smooth` (those C* was fitted to, e.g.
    /// with the walls' continuations across periodic seams) instead of targets rebuilt from
    /// `fit`.
    pub fn with_targets(
        space: &'a dyn FitSpace,
        mesh: &LinearMesh,
        topo: &Topology,
        fit: &FitParams,
        smooth: Option<&crate::fit::SmoothTargets>,
        c_star: &[[f64; 3]],
        params: &EnergyParams,
    ) -> Result<Self, EnergyError> {
        let weight = params.weight;
        if !(weight >= 0.0 && weight.is_finite()) {
            return Err(EnergyError::Weight(weight));
        }
        let dim = space.dim();
        let nb = net_len(dim);
        // The fit's own normal equations (features and their weights included), so the
        // least-squares term is the one C* minimises.
        let (k, rhs) = crate::fit::normal_equations_with(space, mesh, topo, fit, smooth);
        // Across rotation seams the fit's matrix couples the coordinates (K ⊗ I₃ + C), and C*
        // minimises that one.
        let coupling = space.has_frames().then(|| {
            let features = fit.features.as_deref();
            let blocks =
                crate::fit::ElementBlocks::with_features(space, mesh, topo, &fit.weights, features);
            crate::fit::rotated::Coupling::of(space, &blocks).expect("a space with frames")
        });
        let c0 = space.control_points();
        let ls_offset: f64 = c_star
            .iter()
            .zip(c0)
            .zip(&rhs)
            .map(|((s, c), r)| (0..3).map(|i| (s[i] - c[i]) * r[i]).sum::<f64>())
            .sum();
        // Tensor Gauss rule.
        let nz = if dim == 2 { 1 } else { 3 };
        let (mut qw, mut dbq, mut qu) = (Vec::new(), Vec::new(), Vec::new());
        for qz in 0..nz {
            for qy in 0..3 {
                for qx in 0..3 {
                    let u = [
                        GAUSS3[qx].0,
                        GAUSS3[qy].0,
                        if dim == 2 { 0.0 } else { GAUSS3[qz].0 },
                    ];
                    let w = GAUSS3[qx].1 * GAUSS3[qy].1 * if dim == 2 { 1.0 } else { GAUSS3[qz].1 };
                    let b = u.map(bernstein2);
                    let db = u.map(bernstein2_derivative);
                    let mut g = [[0.0; 27]; 3];
                    for c in 0..nz {
                        for bb in 0..3 {
                            for a in 0..3 {
                                let o = a + 3 * bb + 9 * c;
                                let bz = if dim == 2 { 1.0 } else { b[2][c] };
                                g[0][o] = db[0][a] * b[1][bb] * bz;
                                g[1][o] = b[0][a] * db[1][bb] * bz;
                                if dim == 3 {
                                    g[2][o] = b[0][a] * b[1][bb] * db[2][c];
                                }
                            }
                        }
                    }
                    qw.push(w);
                    dbq.push(g);
                    qu.push(u);
                }
            }
        }
        let nq = qw.len();
        let per_element: Vec<(Vec<DMat3>, f64, ElementRows)> = (0..space.n_elements())
            .into_par_iter()
            .map(|e| {
                // The straight element's degree-elevated net: its multilinear map at the lattice.
                let net = elevated_net(dim, &mesh.element_coords(e));
                let mut pinv = Vec::with_capacity(nq);
                let mut vol = 0.0;
                for q in 0..nq {
                    let j0 = jacobian(dim, nb, &net, &dbq[q]);
                    let (p, det) = inverse(&j0);
                    vol += qw[q] * det;
                    pinv.push(p);
                }
                let (mut o, mut c, mut w) = (Vec::new(), Vec::new(), Vec::new());
                space.element_rows(e, &mut o, &mut c, &mut w);
                let mut ids = c.clone();
                ids.sort_unstable();
                ids.dedup();
                let m = ids.len();
                let mut r = vec![0.0; nb * m];
                for a in 0..nb {
                    for k in o[a]..o[a + 1] {
                        r[a * m + ids.binary_search(&c[k]).unwrap()] += w[k];
                    }
                }
                (pinv, vol.abs(), ElementRows { ids, r })
            })
            .collect();
        let mut frozen = vec![false; c0.len()];
        for (e, (_, _, rows)) in per_element.iter().enumerate() {
            let m = rows.ids.len();
            for side in 0..2 * dim {
                if topo.neighbor(e, side) != crate::mesh::topology::NONE {
                    continue;
                }
                let (k, at) = (side / 2, 2 * (side % 2));
                for a in 0..nb {
                    if [a % 3, (a / 3) % 3, a / 9][k] != at {
                        continue;
                    }
                    for (j, &id) in rows.ids.iter().enumerate() {
                        if rows.r[a * m + j] != 0.0 {
                            frozen[id as usize] = true;
                        }
                    }
                }
            }
        }
        let rotated = per_element
            .iter()
            .enumerate()
            .map(|(e, (_, _, r))| match space.frames(e) {
                Some(frames) => frames
                    .iter()
                    .filter_map(|(g, m)| {
                        let k = r.ids.binary_search(g).ok()?;
                        Some((k as u32, *m))
                    })
                    .collect(),
                None => Vec::new(),
            })
            .collect();
        let mut pinv = Vec::with_capacity(nq * per_element.len());
        let mut scale = Vec::with_capacity(per_element.len());
        let mut rows = Vec::with_capacity(per_element.len());
        let h_min = per_element
            .iter()
            .map(|p| p.1.abs().powf(1.0 / dim as f64))
            .fold(f64::INFINITY, f64::min);
        let mean = per_element.iter().map(|p| p.1).sum::<f64>() / per_element.len().max(1) as f64;
        for (p, vol, r) in per_element {
            pinv.extend(p);
            let v = match params.scale {
                EnergyScale::Element => vol,
                EnergyScale::Mean => mean,
            };
            scale.push(weight * v.powf(2.0 / dim as f64));
            rows.push(r);
        }
        Ok(Energy {
            space,
            dim,
            nb,
            weight,
            k,
            rhs,
            ls_offset,
            qw,
            dbq,
            pinv,
            scale,
            rows,
            shifts: (0..space.n_elements())
                .map(|e| space.net_shift(e).map(Box::new))
                .collect(),
            rotated,
            coupling,
            h_min,
            frozen,
        })
    }

    pub fn n_elements(&self) -> usize {
        self.rows.len()
    }

    /// Whether control point `i` carries the boundary and is therefore kept fixed.
    pub fn is_frozen(&self, i: usize) -> bool {
        self.frozen[i]
    }

    /// The distinct control points element e depends on (sorted).
    pub fn element_control_points(&self, e: usize) -> &[u32] {
        &self.rows[e].ids
    }

    pub(crate) fn nq(&self) -> usize {
        self.qw.len()
    }

    /// Bernstein net of element e for control points `cps` (from the cached rows).
    pub(crate) fn net(&self, e: usize, cps: &[[f64; 3]]) -> BezierNet {
        let ElementRows { ids, r } = &self.rows[e];
        let m = ids.len();
        // The control points as the element sees them (rotated across a seam; the few
        // elements along rotation seams only).
        let seen = (!self.rotated[e].is_empty()).then(|| {
            let mut seen: Vec<[f64; 3]> = ids.iter().map(|&id| cps[id as usize]).collect();
            for &(k, ref rm) in &self.rotated[e] {
                seen[k as usize] = rotate(rm, seen[k as usize]);
            }
            seen
        });
        let mut net = [[0.0; 3]; 27];
        for a in 0..self.nb {
            for (k, &id) in ids.iter().enumerate() {
                let w = r[a * m + k];
                if w != 0.0 {
                    let c = seen.as_ref().map_or(cps[id as usize], |s| s[k]);
                    for i in 0..3 {
                        net[a][i] += w * c[i];
                    }
                }
            }
        }
        if let Some(s) = &self.shifts[e] {
            for (x, d) in net.iter_mut().zip(s.iter()) {
                for i in 0..3 {
                    x[i] += d[i];
                }
            }
        }
        net
    }

    /// M_q = J(u_q) P_q of element e with Bernstein net `net`.
    pub(crate) fn m_at(&self, e: usize, q: usize, net: &BezierNet) -> DMat3 {
        let j = jacobian(self.dim, self.nb, net, &self.dbq[q]);
        j * self.pinv[e * self.nq() + q]
    }

    /// w_e S_e of element e with Bernstein net `net`; with `grad`, ∂(w_e S_e)/∂B is added into
    /// it (nb × 3).
    fn element_energy(&self, e: usize, net: &BezierNet, mut grad: Option<&mut BezierNet>) -> f64 {
        let nq = self.nq();
        let mut s = 0.0;
        for q in 0..nq {
            let m = self.m_at(e, q, net);
            let mut g = DMat3::ZERO;
            let f = dirichlet(self.dim, &m, grad.as_ref().map(|_| &mut g));
            if !f.is_finite() {
                return f64::INFINITY;
            }
            s += self.qw[q] * f;
            if let Some(out) = grad.as_deref_mut() {
                // H = w_q (∂f/∂M) Pᵀ; ∂/∂B_a = H ∇b_a.
                let p = &self.pinv[e * nq + q];
                let h = g * p.transpose() * (self.qw[q] * self.scale[e]);
                let rows = [h.row(0), h.row(1), h.row(2)];
                let db = &self.dbq[q];
                for a in 0..self.nb {
                    let dba = DVec3::new(db[0][a], db[1][a], db[2][a]);
                    for i in 0..self.dim {
                        out[a][i] += rows[i].dot(dba);
                    }
                }
            }
        }
        self.scale[e] * s
    }

    /// w_e Σ_e S_e and its per-element parts (+∞ when an element has det J ≤ 0 somewhere).
    pub fn degeneration(&self, cps: &[[f64; 3]]) -> Vec<f64> {
        (0..self.n_elements())
            .into_par_iter()
            .map(|e| self.element_energy(e, &self.net(e, cps), None))
            .collect()
    }

    /// The least-squares term (δ − δ*)ᵀ K (δ − δ*) and, with `grad`, its gradient written to it.
    fn least_squares(&self, cps: &[[f64; 3]], grad: Option<&mut [[f64; 3]]>) -> f64 {
        let c0 = self.space.control_points();
        let delta: Vec<[f64; 3]> = cps
            .iter()
            .zip(c0)
            .map(|(c, z)| [c[0] - z[0], c[1] - z[1], c[2] - z[2]])
            .collect();
        let mut kd = vec![[0.0; 3]; delta.len()];
        self.k.apply(&delta, &mut kd);
        if let Some(c) = &self.coupling {
            c.apply_add(&delta, &mut kd);
        }
        let parts: Vec<f64> = delta
            .par_chunks(4096)
            .zip(kd.par_chunks(4096))
            .zip(self.rhs.par_chunks(4096))
            .map(|((d, k), r)| {
                let mut s = 0.0;
                for i in 0..d.len() {
                    for c in 0..3 {
                        s += d[i][c] * (k[i][c] - 2.0 * r[i][c]);
                    }
                }
                s
            })
            .collect();
        if let Some(g) = grad {
            for i in 0..g.len() {
                for c in 0..3 {
                    g[i][c] = 2.0 * (kd[i][c] - self.rhs[i][c]);
                }
            }
        }
        parts.iter().sum::<f64>() + self.ls_offset
    }

    /// Q(C).
    pub fn value(&self, cps: &[[f64; 3]]) -> f64 {
        let s: f64 = self.degeneration(cps).iter().sum();
        if !s.is_finite() {
            return f64::INFINITY;
        }
        self.least_squares(cps, None) + s
    }

    /// Q(C) and ∇Q(C) (zero z components in 2D).
    pub fn value_and_gradient(&self, cps: &[[f64; 3]], grad: &mut [[f64; 3]]) -> f64 {
        let ls = self.least_squares(cps, Some(grad));
        let parts: Vec<(f64, Vec<[f64; 3]>)> = (0..self.n_elements())
            .into_par_iter()
            .map(|e| {
                let mut gb = [[0.0; 3]; 27];
                let s = self.element_energy(e, &self.net(e, cps), Some(&mut gb));
                let ElementRows { ids, r } = &self.rows[e];
                let m = ids.len();
                let mut gc = vec![[0.0; 3]; m];
                for a in 0..self.nb {
                    for k in 0..m {
                        let w = r[a * m + k];
                        if w != 0.0 {
                            for i in 0..3 {
                                gc[k][i] += w * gb[a][i];
                            }
                        }
                    }
                }
                // A point seen as R C takes Rᵀ of its share.
                for &(k, ref rm) in &self.rotated[e] {
                    gc[k as usize] = rotate_back(rm, gc[k as usize]);
                }
                (s, gc)
            })
            .collect();
        let mut s = 0.0;
        for (e, (se, gc)) in parts.iter().enumerate() {
            s += se;
            for (k, &id) in self.rows[e].ids.iter().enumerate() {
                for i in 0..3 {
                    grad[id as usize][i] += gc[k][i];
                }
            }
        }
        if self.dim == 2 {
            for g in grad.iter_mut() {
                g[2] = 0.0;
            }
        }
        if !s.is_finite() {
            return f64::INFINITY;
        }
        ls + s
    }

    /// [`Energy::value_and_gradient`] with the gradient of the frozen (boundary) control points
    /// zeroed: the gradient of Q restricted to the free control points, so no L-BFGS direction
    /// (built from these gradients and the steps they make) ever moves the boundary.
    pub(crate) fn value_and_free_gradient(&self, cps: &[[f64; 3]], grad: &mut [[f64; 3]]) -> f64 {
        let q = self.value_and_gradient(cps, grad);
        for (g, &f) in grad.iter_mut().zip(&self.frozen) {
            if f {
                *g = [0.0; 3];
            }
        }
        q
    }

    /// Per-element certified lower bounds of det J for control points `cps`.
    pub(crate) fn bounds(
        &self,
        certifier: &dyn Certifier,
        cps: &[[f64; 3]],
        depth: usize,
    ) -> Vec<f64> {
        let all: Vec<usize> = (0..self.n_elements()).collect();
        certifier
            .certify(self.dim, &all, &|e| self.net(e, cps), depth)
            .iter()
            .map(|b| b.lower)
            .collect()
    }
}

/// R v (R by rows).
pub(crate) fn rotate(r: &Mat3, v: [f64; 3]) -> [f64; 3] {
    std::array::from_fn(|i| r[i][0] * v[0] + r[i][1] * v[1] + r[i][2] * v[2])
}

/// Rᵀ v (R by rows).
pub(crate) fn rotate_back(r: &Mat3, v: [f64; 3]) -> [f64; 3] {
    std::array::from_fn(|i| r[0][i] * v[0] + r[1][i] * v[1] + r[2][i] * v[2])
}

/// J = Σ_a B_a ⊗ ∇b_a (J₃₃ = 1 in 2D).
pub(crate) fn jacobian(dim: usize, nb: usize, net: &BezierNet, db: &[[f64; 27]; 3]) -> DMat3 {
    // Column k is ∂x/∂u_k.
    let mut j = [DVec3::ZERO; 3];
    for a in 0..nb {
        for i in 0..dim {
            for (k, col) in j.iter_mut().enumerate().take(dim) {
                col[i] += net[a][i] * db[k][a];
            }
        }
    }
    if dim == 2 {
        j[2][2] = 1.0;
    }
    DMat3::from_cols(j[0], j[1], j[2])
}

/// How the minimisers decide that a candidate keeps the mesh valid: element e is accepted when
/// its certified lower bound of det J exceeds `threshold[e]`.
pub struct Validity<'c> {
    pub certifier: &'c dyn Certifier,
    pub depth: usize,
    pub threshold: Vec<f64>,
}

impl Validity<'_> {
    /// Thresholds for `start`: `requested[e]` (0 where the slice is short), lowered to half of
    /// what `start` achieves where it achieves less, so the start is always accepted.
    pub fn for_start<'c>(
        energy: &Energy,
        certifier: &'c dyn Certifier,
        depth: usize,
        requested: &[f64],
        start: &[[f64; 3]],
    ) -> Result<Validity<'c>, EnergyError> {
        let lower = energy.bounds(certifier, start, depth);
        let mut threshold = Vec::with_capacity(lower.len());
        for (e, &l) in lower.iter().enumerate() {
            if !(l > 0.0) {
                return Err(EnergyError::UncertifiedStart { element: e });
            }
            let t = requested.get(e).copied().unwrap_or(0.0).max(0.0);
            threshold.push(if l > t { t } else { 0.5 * l });
        }
        Ok(Validity {
            certifier,
            depth,
            threshold,
        })
    }

    /// Every element of `cps` passes its threshold.
    pub fn accepts(&self, energy: &Energy, cps: &[[f64; 3]]) -> bool {
        energy
            .bounds(self.certifier, cps, self.depth)
            .iter()
            .zip(&self.threshold)
            .all(|(l, t)| *l > *t)
    }
}

/// Minimise Q from `start` with the solver in `params`; `observe` sees every accepted iterate.
pub fn minimize(
    energy: &Energy,
    validity: &Validity,
    start: &[[f64; 3]],
    params: &EnergyParams,
    observe: &mut dyn FnMut(&[[f64; 3]]),
) -> Result<(Vec<[f64; 3]>, EnergyInfo), EnergyError> {
    minimize_on(
        energy,
        validity,
        start,
        params,
        &colored::CpuEnergyKernel,
        observe,
    )
}

/// [`minimize`] on `kernel` (an executor): the coloured solver takes its local derivatives from it where
/// it computes them (the GPU's `local_newton` kernel).
pub fn minimize_on(
    energy: &Energy,
    validity: &Validity,
    start: &[[f64; 3]],
    params: &EnergyParams,
    kernel: &dyn EnergyKernel,
    observe: &mut dyn FnMut(&[[f64; 3]]),
) -> Result<(Vec<[f64; 3]>, EnergyInfo), EnergyError> {
    let t = Instant::now();
    let deg = |c: &[[f64; 3]]| {
        let parts = energy.degeneration(c);
        let s: f64 = parts.iter().sum();
        (parts, s / energy.weight.max(f64::MIN_POSITIVE))
    };
    let (parts, initial_degeneration) = deg(start);
    if let Some(e) = parts.iter().position(|s| !s.is_finite()) {
        return Err(EnergyError::InfiniteStart { element: e });
    }
    let (c, mut info) = match params.solver {
        EnergySolver::Lbfgs => lbfgs::lbfgs(energy, validity, start, params, observe),
        EnergySolver::Colored => {
            colored::minimize(energy, validity, start, params, kernel, observe)
                .map_err(|e| EnergyError::Gpu(e.to_string()))?
        }
    };
    info.initial_degeneration = initial_degeneration;
    info.final_degeneration = deg(&c).1;
    info.seconds = t.elapsed().as_secs_f64();
    Ok((c, info))
}

#[cfg(test)]
mod tests {
    use super::{Energy, EnergyParams};
    use crate::fit::rotated::tests::sector_and_ring;
    use crate::fit::{FitParams, FitSolver};
    use crate::spline::SplineSpace;
    use crate::spline::seam::{interior_view, unwrap};

    /// The degeneration energy on the rotation-glued sector of `fit::rotated`'s tests: each element's net
    /// sees the points across the seam rotated, so its energy is the ring's element's at the
    /// fitted maps (which agree, above); the least-squares term couples the coordinates as
    /// the fit does, so it vanishes at the coupled fit's C*; and the gradient (Rᵀ on the
    /// rotated points' shares) is the value's by central differences.
    #[test]
    fn the_energy_sees_the_seam_as_the_ring_does() {
        let (sector, ring, st, rt, glued) = sector_and_ring();
        let mut space = SplineSpace::build_with_knots(&glued.mesh, &glued.topo, &[], None);
        unwrap(&mut space, &sector, &st, &glued).expect("the seam is identified");
        let whole = SplineSpace::build_with_knots(&ring, &rt, &[], None);
        let view = interior_view(&sector, &st, &glued);
        let mut params = FitParams::default();
        params.cg.rel_tol = 1e-13;
        params.solver = FitSolver::Cholesky;
        let (cs, _) = crate::fit::fit(&space, &sector, &view.topo, &params, |_, _| {}).unwrap();
        let (cr, _) = crate::fit::fit(&whole, &ring, &rt, &params, |_, _| {}).unwrap();
        let ep = EnergyParams::default();
        let es = Energy::new(&space, &sector, &view.topo, &params, &cs, &ep).unwrap();
        let er = Energy::new(&whole, &ring, &rt, &params, &cr, &ep).unwrap();
        let (ds, dr) = (es.degeneration(&cs), er.degeneration(&cr));
        for e in 0..sector.n_elements() {
            assert!(
                (ds[e] - dr[e]).abs() <= 1e-9 * dr[e].abs().max(1e-12),
                "element {e}: {} on the sector, {} on the ring",
                ds[e],
                dr[e]
            );
        }
        let total: f64 = ds.iter().sum();
        let ls = es.value(&cs) - total;
        assert!(ls.abs() <= 1e-9 * total, "least-squares term {ls:e} at C*");
        // Between the initial map and C*, off any symmetry.
        let c: Vec<[f64; 3]> = (space.control_points.iter().zip(&cs).enumerate())
            .map(|(i, (a, b))| {
                let w = 0.3 + 0.4 * ((i as f64) * 0.77).sin().abs();
                [a[0] + w * (b[0] - a[0]), a[1] + w * (b[1] - a[1]), 0.0]
            })
            .collect();
        let mut g = vec![[0.0; 3]; c.len()];
        es.value_and_gradient(&c, &mut g);
        let gmax = g.iter().flatten().fold(0.0f64, |a, b| a.max(b.abs()));
        let h = 1e-7;
        let rotated: Vec<u32> = (0..sector.n_elements())
            .filter_map(|e| space.extraction.frames(e))
            .flat_map(|f| f.iter().map(|f| f.0))
            .collect();
        assert!(!rotated.is_empty());
        for &i in &rotated {
            for k in 0..2 {
                let (mut cp, mut cm) = (c.clone(), c.clone());
                cp[i as usize][k] += h;
                cm[i as usize][k] -= h;
                let fd = (es.value(&cp) - es.value(&cm)) / (2.0 * h);
                let an = g[i as usize][k];
                assert!(
                    (fd - an).abs() <= 1e-5 * gmax,
                    "control point {i} component {k}: finite difference {fd}, analytic {an}"
                );
            }
        }
    }
}
