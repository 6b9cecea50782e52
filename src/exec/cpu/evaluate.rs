//! CPU twin of `shaders/evaluate.wgsl`.

use super::{Real, Vec4};

/// Uniform block of `evaluate.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, bytemuck::Pod, bytemuck::Zeroable)]
pub struct Params {
    pub dim: u32,
    pub n_queries: u32,
    pub with_derivs: u32,
    pub _pad: u32,
}
const _: () = assert!(std::mem::size_of::<Params>() == 16);

fn bernstein2<T: Real>(t: T) -> [T; 3] {
    let s = T::of(1.0) - t;
    [s * s, T::of(2.0) * s * t, t * t]
}

fn bernstein2_derivative<T: Real>(t: T) -> [T; 3] {
    [
        T::of(-2.0) * (T::of(1.0) - t),
        T::of(2.0) - T::of(4.0) * t,
        T::of(2.0) * t,
    ]
}

/// One invocation per query `q`, as in the shader.
pub fn evaluate<T: Real>(
    params: &Params,
    nets: &[T],
    xi: &[Vec4<T>],
    queries: &[[u32; 2]],
    points: &mut [T],
    derivs: &mut [T],
) {
    for q in 0..params.n_queries as usize {
        let e = queries[q][0] as usize;
        let t = xi[queries[q][1] as usize];
        let bu = bernstein2(t[0]);
        let bv = bernstein2(t[1]);
        let du = bernstein2_derivative(t[0]);
        let dv = bernstein2_derivative(t[1]);
        let mut bw = [T::of(1.0), T::of(0.0), T::of(0.0)];
        let mut dw = [T::of(0.0); 3];
        let mut nz = 1;
        if params.dim == 3 {
            bw = bernstein2(t[2]);
            dw = bernstein2_derivative(t[2]);
            nz = 3;
        }
        let mut x = [T::of(0.0); 3];
        let mut xu = [T::of(0.0); 3];
        let mut xv = [T::of(0.0); 3];
        let mut xw = [T::of(0.0); 3];
        for c in 0..nz {
            for b in 0..3 {
                for a in 0..3 {
                    let o = e * 81 + (9 * c + 3 * b + a) * 3;
                    let p = [nets[o], nets[o + 1], nets[o + 2]];
                    for k in 0..3 {
                        x[k] += (bu[a] * bv[b] * bw[c]) * p[k];
                        xu[k] += (du[a] * bv[b] * bw[c]) * p[k];
                        xv[k] += (bu[a] * dv[b] * bw[c]) * p[k];
                        xw[k] += (bu[a] * bv[b] * dw[c]) * p[k];
                    }
                }
            }
        }
        points[3 * q..3 * q + 3].copy_from_slice(&x);
        if params.with_derivs != 0 {
            let o = 9 * q;
            derivs[o..o + 3].copy_from_slice(&xu);
            derivs[o + 3..o + 6].copy_from_slice(&xv);
            derivs[o + 6..o + 9].copy_from_slice(&xw);
        }
    }
}
