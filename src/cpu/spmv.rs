//! CPU twin of `shaders/spmv.wgsl`.

use super::{Real, Vec4};
pub use crate::gpu::cg::SpmvParams;

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
