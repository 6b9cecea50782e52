//! CPU twin of `shaders/cg.wgsl`: second reduction stage with α/β, and the vector updates.
//! Its α and β are the CPU solvers' arithmetic ([`step_lengths`], [`direction_weights`]) at
//! the kernel's precision; which components run is the shader's test (rᵀr > target² in that
//! precision). Coupled (`CgKernelParams::coupled`), the finalisers run the one recurrence
//! of the CPU's coupled CG (`solve::Coupled`): each reduction's three lanes summed into lane 0,
//! lane 0's α and β stepping all three.

use super::{Real, Vec4};
use crate::solve::{direction_weights, step_lengths};

/// Uniform block of `cg.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, bytemuck::Pod, bytemuck::Zeroable)]
pub struct CgKernelParams {
    pub n: u32,
    pub n_partials: u32,
    pub max_iters: u32,
    /// 1: one recurrence over the three lanes (the fit's coupled system across rotation
    /// seams), 0: one per lane.
    pub coupled: u32,
}
const _: () = assert!(std::mem::size_of::<CgKernelParams>() == 16);

/// `State` of cg.wgsl.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, bytemuck::Pod, bytemuck::Zeroable)]
pub struct CgState {
    pub iterations: u32,
    pub done: u32,
    pub breakdown: u32,
    pub _pad: u32,
}
const _: () = assert!(std::mem::size_of::<CgState>() == 16);

/// Workgroup size of the finalize entry points.
pub const WG: usize = 256;

/// `Scalars` of the shader.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Scalars<T> {
    pub rz: Vec4<T>,
    pub rr: Vec4<T>,
    pub target2: Vec4<T>,
    pub alpha: Vec4<T>,
    pub beta: Vec4<T>,
    pub pap: Vec4<T>,
}

/// The three components of a lane vector (the fourth is zero).
fn head<T: Real>(v: Vec4<T>) -> [T; 3] {
    [v[0], v[1], v[2]]
}

fn add<T: Real>(a: Vec4<T>, b: Vec4<T>) -> Vec4<T> {
    std::array::from_fn(|k| a[k] + b[k])
}

/// The three lanes' sum in lane 0 (coupled), or `v` itself: the shader's `sums`.
fn sums<T: Real>(params: &CgKernelParams, v: Vec4<T>) -> Vec4<T> {
    if params.coupled != 0 {
        let z = T::of(0.0);
        return [v[0] + v[1] + v[2], z, z, z];
    }
    v
}

/// Lane 0 on the three lanes (coupled), or `v` itself: the shader's `steps`.
fn steps<T: Real>(params: &CgKernelParams, v: Vec4<T>) -> Vec4<T> {
    if params.coupled != 0 {
        return [v[0], v[0], v[0], T::of(0.0)];
    }
    v
}

/// Sum the partial pairs into (a·b, a·a) with the shader's lane order and tree.
fn reduce_partials<T: Real>(params: &CgKernelParams, partials: &[Vec4<T>]) -> (Vec4<T>, Vec4<T>) {
    let mut s0 = [[T::of(0.0); 4]; WG];
    let mut s1 = [[T::of(0.0); 4]; WG];
    for l in 0..WG {
        let mut g = l;
        while g < params.n_partials as usize {
            s0[l] = add(s0[l], partials[2 * g]);
            s1[l] = add(s1[l], partials[2 * g + 1]);
            g += WG;
        }
    }
    let mut h = WG / 2;
    while h > 0 {
        for l in 0..h {
            s0[l] = add(s0[l], s0[l + h]);
            s1[l] = add(s1[l], s1[l + h]);
        }
        h /= 2;
    }
    (s0[0], s1[0])
}

pub fn finalize_alpha<T: Real>(
    params: &CgKernelParams,
    scalars: &mut Scalars<T>,
    state: &mut CgState,
    partials: &[Vec4<T>],
) {
    let (pap, _) = reduce_partials(params, partials);
    let pap = sums(params, pap);
    let mut alpha = [T::of(0.0); 4];
    let mut running = false;
    if state.done == 0 && state.breakdown == 0 {
        for k in 0..3 {
            if scalars.rr[k] > scalars.target2[k] {
                running = true;
            }
        }
        if running && state.iterations >= params.max_iters {
            running = false;
        }
        if running {
            let active = std::array::from_fn(|k| scalars.rr[k] > scalars.target2[k]);
            match step_lengths(active, head(scalars.rz), head(pap)) {
                Ok([a0, a1, a2]) => alpha = [a0, a1, a2, T::of(0.0)],
                Err(_) => state.breakdown = state.iterations + 1,
            }
            state.iterations += 1;
        } else {
            state.done = 1;
        }
    }
    scalars.pap = pap;
    scalars.alpha = steps(params, alpha);
}

#[allow(clippy::too_many_arguments)]
pub fn update_xr<T: Real>(
    params: &CgKernelParams,
    scalars: &Scalars<T>,
    x: &mut [Vec4<T>],
    r: &mut [Vec4<T>],
    z: &mut [Vec4<T>],
    p: &[Vec4<T>],
    ap: &[Vec4<T>],
    inv_diag: &[T],
) {
    let alpha = scalars.alpha;
    for i in 0..params.n as usize {
        for k in 0..4 {
            x[i][k] += alpha[k] * p[i][k];
            r[i][k] -= alpha[k] * ap[i][k];
            z[i][k] = inv_diag[i] * r[i][k];
        }
    }
}

pub fn finalize_beta<T: Real>(
    params: &CgKernelParams,
    scalars: &mut Scalars<T>,
    state: &CgState,
    partials: &[Vec4<T>],
) {
    let (rz_new, rr_new) = reduce_partials(params, partials);
    let (rz_new, rr_new) = (sums(params, rz_new), sums(params, rr_new));
    let mut beta = [T::of(0.0); 4];
    if state.done == 0 {
        let [b0, b1, b2] = direction_weights(head(scalars.rz), head(rz_new));
        beta = [b0, b1, b2, T::of(0.0)];
        scalars.rz = rz_new;
        scalars.rr = rr_new;
    }
    scalars.beta = steps(params, beta);
}

pub fn update_p<T: Real>(
    params: &CgKernelParams,
    scalars: &Scalars<T>,
    z: &[Vec4<T>],
    p: &mut [Vec4<T>],
) {
    for i in 0..params.n as usize {
        for k in 0..4 {
            p[i][k] = z[i][k] + scalars.beta[k] * p[i][k];
        }
    }
}
