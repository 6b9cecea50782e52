//! CPU twin of `shaders/spmv.wgsl`.

use super::{Real, Vec4};

/// Uniform block of `spmv.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, bytemuck::Pod, bytemuck::Zeroable)]
pub struct SpmvParams {
    pub n_rows: u32,
    pub row_base: u32,
    pub _pad0: u32,
    pub _pad1: u32,
}
const _: () = assert!(std::mem::size_of::<SpmvParams>() == 16);

/// One invocation per row `r` of the block.
pub fn spmv<T: Real>(
    params: &SpmvParams,
    indptr: &[u32],
    indices: &[u32],
    data: &[T],
    x: &[Vec4<T>],
    y: &mut [Vec4<T>],
) {
    for r in 0..params.n_rows as usize {
        let mut s = [T::of(0.0); 4];
        for k in indptr[r] as usize..indptr[r + 1] as usize {
            let xv = x[indices[k] as usize];
            for c in 0..4 {
                s[c] += data[k] * xv[c];
            }
        }
        y[params.row_base as usize + r] = s;
    }
}
