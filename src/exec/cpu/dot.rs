//! CPU twin of `shaders/dot.wgsl` (first reduction stage).

use super::{Real, Vec4};

/// Uniform block of `dot.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, bytemuck::Pod, bytemuck::Zeroable)]
pub struct DotParams {
    pub n: u32,
    pub _pad0: u32,
    pub _pad1: u32,
    pub _pad2: u32,
}
const _: () = assert!(std::mem::size_of::<DotParams>() == 16);

/// Workgroup size of the shader.
pub const WG: usize = 256;

fn add<T: Real>(a: Vec4<T>, b: Vec4<T>) -> Vec4<T> {
    std::array::from_fn(|k| a[k] + b[k])
}

/// `n_workgroups` workgroups of [`WG`] lanes: grid-strided sums, then a tree reduction.
pub fn dot_partial<T: Real>(
    params: &DotParams,
    a: &[Vec4<T>],
    b: &[Vec4<T>],
    partials: &mut [Vec4<T>],
    n_workgroups: usize,
) {
    let stride = n_workgroups * WG;
    for wid in 0..n_workgroups {
        let mut sab = [[T::of(0.0); 4]; WG];
        let mut saa = [[T::of(0.0); 4]; WG];
        for lid in 0..WG {
            let mut ab = [T::of(0.0); 4];
            let mut aa = [T::of(0.0); 4];
            let mut i = wid * WG + lid;
            while i < params.n as usize {
                let x = a[i];
                ab = add(ab, std::array::from_fn(|k| x[k] * b[i][k]));
                aa = add(aa, std::array::from_fn(|k| x[k] * x[k]));
                i += stride;
            }
            sab[lid] = ab;
            saa[lid] = aa;
        }
        let mut h = WG / 2;
        while h > 0 {
            for lid in 0..h {
                sab[lid] = add(sab[lid], sab[lid + h]);
                saa[lid] = add(saa[lid], saa[lid + h]);
            }
            h /= 2;
        }
        partials[2 * wid] = sab[0];
        partials[2 * wid + 1] = saa[0];
    }
}
