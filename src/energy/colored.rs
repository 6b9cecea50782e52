//! Coloured local minimisation of the energy (paper §2.4, "one vertex at a time").
//!
//! Input: an [`Energy`], a certified start and [`EnergyParams`]. Output: control points whose
//! energy is not higher, every element certified valid after every accepted local step.
//!
//! The control points are coloured greedily so that no two of one colour share an element
//! ([`color_control_points`]). Moving one control point changes only the elements of its support
//! and one row of the least-squares term, so the control points of one colour have independent
//! local problems: they are solved in parallel, and the result does not depend on the thread
//! count. The local problem of control point i, displaced by v, is
//!
//! L_i(v) = K_ii ‖v‖² + 2 v·((K δ)_i − (F − K C0)_i) + Σ_{e ∋ i} Σ_q w_e h_e² w_q f(M_q + v ψ_qᵀ),
//!
//! where ψ_q = Pᵀ Σ_a R_{a,i} ∇b_a(u_q) (the basis function's gradient in input coordinates) and
//! M_q the current M of the element: the change of Q when only C_i moves. Newton steps use the
//! analytic gradient and Hessian of L_i (3×3, or 2×2 in 2D; shifted to positive definite when
//! needed); each step is halved until L_i decreases (Armijo) and every support element stays
//! certified ([`crate::validity::det_jacobian_bounds`] above its threshold).

use super::dirichlet;
use super::{Energy, EnergyInfo, EnergyParams, EnergySolver, EnergyStop, Mat3, Validity};
use crate::math::BezierNet;
use crate::math::linalg::{DMat3, DVec3, from_dmat3, inverse, to_dmat3};
use crate::validity::det_jacobian_bounds;
use rayon::prelude::*;

/// Greedy colouring of the control points: `color[i] != color[j]` whenever i and j are both
/// in the support of one element. Control points are visited in index order (deterministic).
pub fn color_control_points(n: usize, element_ids: &[&[u32]]) -> Vec<u32> {
    let mut elements_of: Vec<Vec<u32>> = vec![Vec::new(); n];
    for (e, ids) in element_ids.iter().enumerate() {
        for &i in *ids {
            elements_of[i as usize].push(e as u32);
        }
    }
    let mut color = vec![u32::MAX; n];
    let mut used: Vec<bool> = Vec::new();
    for i in 0..n {
        used.iter_mut().for_each(|u| *u = false);
        for &e in &elements_of[i] {
            for &j in element_ids[e as usize] {
                let c = color[j as usize];
                if c != u32::MAX {
                    if c as usize >= used.len() {
                        used.resize(c as usize + 1, false);
                    }
                    used[c as usize] = true;
                }
            }
        }
        let c = used.iter().position(|u| !u).unwrap_or(used.len());
        color[i] = c as u32;
    }
    color
}

/// What the coloured sweeps need of an executor, as the searches need a
/// [`Certifier`](crate::validity::Certifier): the value, gradient and Hessian of each local
/// problem at its current point, or `None` where the caller computes them itself inside its
/// Newton loop ([`CpuEnergyKernel`]). The executors implement it (the GPU with its
/// `local_newton` kernel), so the energy knows nothing of devices.
pub trait EnergyKernel {
    /// The derivatives of `problems` (of dimension `dim`), in their order.
    fn local_derivatives(
        &self,
        dim: usize,
        problems: &[LocalProblem],
    ) -> Result<Option<Vec<LocalDerivatives>>, KernelError>;
}

/// A device failure under an [`EnergyKernel`], in the device's words.
#[derive(Debug, thiserror::Error)]
#[error("{0}")]
pub struct KernelError(pub String);

/// The CPU reference: the sweeps compute every derivative themselves.
pub struct CpuEnergyKernel;

impl EnergyKernel for CpuEnergyKernel {
    fn local_derivatives(
        &self,
        _dim: usize,
        _problems: &[LocalProblem],
    ) -> Result<Option<Vec<LocalDerivatives>>, KernelError> {
        Ok(None)
    }
}

/// Halvings of a local Newton step (2⁻¹² of it is below any useful move).
const LOCAL_BACKTRACKS: usize = 12;

/// One quadrature point of a local problem: w_e h_e² w_q, the current M and ψ.
#[derive(Clone, Copy, Debug)]
pub struct LocalPoint {
    pub w: f64,
    /// Stored by rows ([`Mat3`]): the GPU uploads it as it is.
    pub m: Mat3,
    pub psi: [f64; 3],
}

/// Value, gradient and Hessian of one local problem at v = 0 (`value` is +∞ when some det M ≤ 0).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LocalDerivatives {
    pub value: f64,
    pub gradient: [f64; 3],
    pub hessian: [[f64; 3]; 3],
}

/// The local problem of one control point (see the module docs).
#[derive(Clone, Debug)]
pub struct LocalProblem {
    pub dim: usize,
    pub kii: f64,
    /// (K δ)_i − (F − K C0)_i.
    pub b: [f64; 3],
    pub points: Vec<LocalPoint>,
}

impl LocalProblem {
    /// L_i(v) − L_i(0)'s constant part, with gradient and Hessian when asked.
    pub fn eval(&self, v: [f64; 3], mut grad: Option<(&mut [f64; 3], &mut Mat3)>) -> f64 {
        let d = self.dim;
        let mut l = 0.0;
        for i in 0..d {
            l += self.kii * v[i] * v[i] + 2.0 * self.b[i] * v[i];
        }
        if let Some((g, h)) = grad.as_mut() {
            **g = [0.0; 3];
            **h = [[0.0; 3]; 3];
            for i in 0..d {
                g[i] = 2.0 * self.kii * v[i] + 2.0 * self.b[i];
                h[i][i] = 2.0 * self.kii;
            }
        }
        for p in &self.points {
            let mut m = p.m;
            for i in 0..d {
                for j in 0..3 {
                    m[i][j] += v[i] * p.psi[j];
                }
            }
            let m = to_dmat3(&m);
            let psi = DVec3::from(p.psi);
            let mut gm = DMat3::ZERO;
            let f = dirichlet(d, &m, grad.as_ref().map(|_| &mut gm));
            if !f.is_finite() {
                return f64::INFINITY;
            }
            l += p.w * f;
            if let Some((g, h)) = grad.as_mut() {
                for i in 0..d {
                    g[i] += p.w * gm.row(i).dot(psi);
                }
                // ∂G/∂v_k with dM = e_k ψᵀ: dG = (dM − dT)/d, T = AᵀAAᵀ, dA = −A dM A.
                let (a, _) = inverse(&m);
                let at = a.transpose();
                for k in 0..d {
                    let mut dm = [[0.0; 3]; 3];
                    dm[k] = p.psi;
                    let dm = to_dmat3(&dm);
                    let da = -(a * dm * a);
                    let dat = da.transpose();
                    let r = dm - dat * a * at - at * da * at - at * a * dat;
                    for i in 0..d {
                        // Summed from +0.0 as written: glam's `dot` starts from the first
                        // product, which differs in the sign of an all-zero sum.
                        let (row, mut s) = (r.row(i), 0.0);
                        for j in 0..3 {
                            s += row[j] * p.psi[j];
                        }
                        h[i][k] += p.w * s / d as f64;
                    }
                }
            }
        }
        l
    }
}

/// Solve H x = r for SPD H (d×d) by Cholesky, shifting the diagonal until it factors.
fn solve_spd(d: usize, h: &Mat3, r: [f64; 3]) -> [f64; 3] {
    let scale = (0..d)
        .map(|i| h[i][i].abs())
        .fold(0.0f64, f64::max)
        .max(f64::MIN_POSITIVE);
    let mut shift = 0.0;
    loop {
        let mut l = [[0.0; 3]; 3];
        let mut ok = true;
        'f: for i in 0..d {
            for j in 0..=i {
                let mut s = h[i][j] + if i == j { shift } else { 0.0 };
                for k in 0..j {
                    s -= l[i][k] * l[j][k];
                }
                if i == j {
                    if !(s > 1e-12 * scale) {
                        ok = false;
                        break 'f;
                    }
                    l[i][i] = s.sqrt();
                } else {
                    l[i][j] = s / l[j][j];
                }
            }
        }
        if ok {
            let mut y = [0.0; 3];
            for i in 0..d {
                y[i] = (r[i] - (0..i).map(|k| l[i][k] * y[k]).sum::<f64>()) / l[i][i];
            }
            let mut x = [0.0; 3];
            for i in (0..d).rev() {
                x[i] = (y[i] - (i + 1..d).map(|k| l[k][i] * x[k]).sum::<f64>()) / l[i][i];
            }
            return x;
        }
        shift = if shift == 0.0 {
            1e-6 * scale
        } else {
            shift * 10.0
        };
    }
}

/// What the local problems share: each control point's support and K_ii.
struct Locals {
    /// Support of each control point: (element, column in the element's rows).
    support: Vec<Vec<(u32, u32)>>,
    kii: Vec<f64>,
}

impl Locals {
    fn new(energy: &Energy) -> Self {
        let n = energy.space.control_points().len();
        let mut support: Vec<Vec<(u32, u32)>> = vec![Vec::new(); n];
        for (e, r) in energy.rows.iter().enumerate() {
            for (k, &i) in r.ids.iter().enumerate() {
                support[i as usize].push((e as u32, k as u32));
            }
        }
        let k = &energy.k;
        let kii = (0..n)
            .map(|i| {
                (k.indptr()[i]..k.indptr()[i + 1])
                    .find(|&p| k.indices()[p] as usize == i)
                    .map_or(0.0, |p| k.data()[p])
            })
            .collect();
        Locals { support, kii }
    }

    /// The local problem of control point i at control points `x` (element nets `nets`).
    fn problem(
        &self,
        energy: &Energy,
        x: &[[f64; 3]],
        nets: &[BezierNet],
        i: usize,
    ) -> LocalProblem {
        let (k, c0) = (&energy.k, energy.space.control_points());
        let (nb, nq) = (energy.nb, energy.nq());
        let mut kd = [0.0; 3];
        for p in k.indptr()[i]..k.indptr()[i + 1] {
            let j = k.indices()[p] as usize;
            for c in 0..3 {
                kd[c] += k.data()[p] * (x[j][c] - c0[j][c]);
            }
        }
        // Across rotation seams the row also takes the coupling's (C δ)_i (C_ii = 0).
        if let Some(c) = &energy.coupling {
            c.row_apply_add(i, &|j| [0, 1, 2].map(|k| x[j][k] - c0[j][k]), &mut kd);
        }
        let b = [0, 1, 2].map(|c| kd[c] - energy.rhs[i][c]);
        let mut points = Vec::with_capacity(self.support[i].len() * nq);
        for &(e, kk) in &self.support[i] {
            let (e, kk) = (e as usize, kk as usize);
            let r = &energy.rows[e];
            // An element that sees the point as R C changes M by (R v) ψᵀ; f and det are
            // invariant under M → Rᵀ M, so the point is Rᵀ M with the same ψ and v.
            let frame = energy.rotated[e].iter().find(|f| f.0 as usize == kk);
            for q in 0..nq {
                let db = &energy.dbq[q];
                let mut phi = [0.0; 3];
                for a in 0..nb {
                    let w = r.r[a * r.ids.len() + kk];
                    for j in 0..3 {
                        phi[j] += w * db[j][a];
                    }
                }
                let p = &energy.pinv[e * nq + q];
                let psi = [0, 1, 2].map(|j| p.col(j).dot(DVec3::from(phi)));
                let mut m = from_dmat3(&energy.m_at(e, q, &nets[e]));
                if let Some((_, rm)) = frame {
                    let rt = crate::math::linalg::transpose(rm);
                    m = std::array::from_fn(|a| {
                        std::array::from_fn(|b| (0..3).map(|c| rt[a][c] * m[c][b]).sum())
                    });
                }
                points.push(LocalPoint {
                    w: energy.qw[q] * energy.scale[e],
                    m,
                    psi,
                });
            }
        }
        LocalProblem {
            dim: energy.dim,
            kii: self.kii[i],
            b,
            points,
        }
    }
}

/// The local problems of control points `which` at control points `x`.
pub fn local_problems(energy: &Energy, x: &[[f64; 3]], which: &[usize]) -> Vec<LocalProblem> {
    let locals = Locals::new(energy);
    let nets: Vec<BezierNet> = (0..energy.n_elements())
        .into_par_iter()
        .map(|e| energy.net(e, x))
        .collect();
    which
        .par_iter()
        .map(|&i| locals.problem(energy, x, &nets, i))
        .collect()
}

/// Minimise by coloured sweeps (see the module docs).
/// Each colour's first Newton step takes its derivatives from `kernel` where it computes
/// them (the GPU's `local_newton` kernel; the line search and certificate stay on the CPU).
pub(crate) fn minimize(
    energy: &Energy,
    validity: &Validity,
    start: &[[f64; 3]],
    params: &EnergyParams,
    kernel: &dyn EnergyKernel,
    observe: &mut dyn FnMut(&[[f64; 3]]),
) -> Result<(Vec<[f64; 3]>, EnergyInfo), KernelError> {
    let n = start.len();
    let dim = energy.dim;
    let nb = energy.nb;
    let ids: Vec<&[u32]> = energy.rows.iter().map(|r| r.ids.as_slice()).collect();
    let color = color_control_points(n, &ids);
    let n_colors = color.iter().map(|&c| c as usize + 1).max().unwrap_or(0);
    let mut by_color: Vec<Vec<u32>> = vec![Vec::new(); n_colors];
    for (i, &c) in color.iter().enumerate() {
        // Boundary control points stay where the least-squares fit put them.
        if !energy.frozen[i] {
            by_color[c as usize].push(i as u32);
        }
    }
    let locals = Locals::new(energy);
    let support = &locals.support;
    let mut x = start.to_vec();
    let mut nets: Vec<BezierNet> = (0..energy.n_elements())
        .into_par_iter()
        .map(|e| energy.net(e, &x))
        .collect();
    let mut f = energy.value(&x);
    let mut info = EnergyInfo::start(EnergySolver::Colored, energy.weight, f);
    info.colors = Some(n_colors);
    while info.iterations < params.max_iterations {
        for cps in &by_color {
            let problems: Vec<LocalProblem> = cps
                .par_iter()
                .map(|&i| locals.problem(energy, &x, &nets, i as usize))
                .collect();
            let first = kernel.local_derivatives(dim, &problems)?;
            let moves: Vec<(u32, [f64; 3], usize, usize)> = cps
                .par_iter()
                .zip(&problems)
                .enumerate()
                .map(|(slot, (&i, lp))| {
                    let i = i as usize;
                    let col = |e: usize, kk: usize, a: usize| {
                        let r = &energy.rows[e];
                        r.r[a * r.ids.len() + kk]
                    };
                    // Newton with a certified Armijo line search on the support elements.
                    let mut v = [0.0; 3];
                    let mut lv = lp.eval(v, None);
                    // Below this predicted decrease a step is rounding noise: w_e h² sums to
                    // the local energy's natural size.
                    let negligible = 1e-12 * lp.points.iter().map(|p| p.w).sum::<f64>();
                    let (mut tried, mut uncertified) = (0, 0);
                    for it in 0..params.local_iterations {
                        let mut g = [0.0; 3];
                        let mut h = [[0.0; 3]; 3];
                        match &first {
                            Some(d) if it == 0 => (g, h) = (d[slot].gradient, d[slot].hessian),
                            _ => {
                                lp.eval(v, Some((&mut g, &mut h)));
                            }
                        }
                        let step = solve_spd(dim, &h, g.map(|x| -x));
                        let slope: f64 = (0..dim).map(|c| g[c] * step[c]).sum();
                        if !(-slope > negligible) {
                            break;
                        }
                        let mut alpha = 1.0;
                        let mut accepted = false;
                        for _ in 0..=params.max_backtracks.min(LOCAL_BACKTRACKS) {
                            tried += 1;
                            let vn = [0, 1, 2].map(|c| v[c] + alpha * step[c]);
                            let ln = lp.eval(vn, None);
                            if ln.is_finite() && ln <= lv + 1e-4 * alpha * slope {
                                let certified = support[i].iter().all(|&(e, kk)| {
                                    let (e, kk) = (e as usize, kk as usize);
                                    let mut net = nets[e];
                                    // The element sees the move as R v across a rotation seam.
                                    let seen = energy.rotated[e]
                                        .iter()
                                        .find(|f| f.0 as usize == kk)
                                        .map_or(vn, |(_, rm)| super::rotate(rm, vn));
                                    for a in 0..nb {
                                        let w = col(e, kk, a);
                                        for c in 0..dim {
                                            net[a][c] += w * seen[c];
                                        }
                                    }
                                    det_jacobian_bounds(dim, &net, validity.depth).lower
                                        > validity.threshold[e]
                                });
                                if certified {
                                    v = vn;
                                    lv = ln;
                                    accepted = true;
                                    break;
                                }
                                uncertified += 1;
                            }
                            alpha *= 0.5;
                        }
                        if !accepted {
                            break;
                        }
                    }
                    (i as u32, v, tried, uncertified)
                })
                .collect();
            for (i, v, tried, uncertified) in moves {
                info.evaluations += tried;
                info.uncertified_trials += uncertified;
                if v == [0.0; 3] {
                    continue;
                }
                let i = i as usize;
                for c in 0..dim {
                    x[i][c] += v[c];
                }
                for &(e, _) in &support[i] {
                    nets[e as usize] = energy.net(e as usize, &x);
                }
            }
        }
        info.iterations += 1;
        observe(&x);
        let fnew = energy.value(&x);
        let decrease = f - fnew;
        f = fnew;
        if decrease <= params.sweep_tol * f.abs().max(f64::MIN_POSITIVE) {
            info.stop = EnergyStop::Stalled;
            break;
        }
    }
    info.final_energy = f;
    Ok((x, info))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The analytic local gradient and Hessian against central differences.
    #[test]
    fn local_derivatives_match_finite_differences() {
        for dim in [2, 3] {
            let m = if dim == 2 {
                [[1.3, 0.2, 0.0], [-0.1, 0.8, 0.0], [0.0, 0.0, 1.0]]
            } else {
                [[1.3, 0.2, 0.1], [-0.1, 0.8, 0.3], [0.05, -0.2, 1.1]]
            };
            let lp = LocalProblem {
                dim,
                kii: 0.7,
                b: [0.3, -0.2, if dim == 2 { 0.0 } else { 0.1 }],
                points: vec![
                    LocalPoint {
                        w: 0.4,
                        m,
                        psi: [0.5, -0.7, if dim == 2 { 0.0 } else { 0.2 }],
                    },
                    LocalPoint {
                        w: 0.6,
                        m: crate::math::linalg::transpose(&m),
                        psi: [-0.3, 0.4, if dim == 2 { 0.0 } else { 0.9 }],
                    },
                ],
            };
            let v = [0.05, -0.03, if dim == 2 { 0.0 } else { 0.02 }];
            let (mut g, mut h) = ([0.0; 3], [[0.0; 3]; 3]);
            lp.eval(v, Some((&mut g, &mut h)));
            let eps = 1e-6;
            for k in 0..dim {
                let mut vp = v;
                let mut vm = v;
                vp[k] += eps;
                vm[k] -= eps;
                let fd = (lp.eval(vp, None) - lp.eval(vm, None)) / (2.0 * eps);
                assert!(
                    (fd - g[k]).abs() < 1e-6 * (1.0 + g[k].abs()),
                    "grad {k}: {fd} vs {}",
                    g[k]
                );
                let (mut gp, mut gm) = ([0.0; 3], [0.0; 3]);
                let mut hh = [[0.0; 3]; 3];
                lp.eval(vp, Some((&mut gp, &mut hh)));
                lp.eval(vm, Some((&mut gm, &mut hh)));
                for i in 0..dim {
                    let fd = (gp[i] - gm[i]) / (2.0 * eps);
                    assert!(
                        (fd - h[i][k]).abs() < 1e-5 * (1.0 + h[i][k].abs()),
                        "H[{i}][{k}]: {fd} vs {}",
                        h[i][k]
                    );
                }
            }
        }
    }

    #[test]
    fn colouring_separates_control_points_of_one_element() {
        let e: Vec<Vec<u32>> = vec![vec![0, 1, 2], vec![1, 2, 3], vec![3, 4, 0], vec![5]];
        let refs: Vec<&[u32]> = e.iter().map(|v| v.as_slice()).collect();
        let c = color_control_points(6, &refs);
        for ids in &e {
            for a in ids {
                for b in ids {
                    assert!(a == b || c[*a as usize] != c[*b as usize]);
                }
            }
        }
    }
}
