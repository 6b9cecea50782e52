//! CPU twin of `shaders/coupling.wgsl`: y += C x over the block rows of the fit's coupling
//! across rotation seams ([`crate::fit::rotated::Coupling`]), after y = K x.

use super::{Real, Vec4};

/// Uniform block of `coupling.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, bytemuck::Pod, bytemuck::Zeroable)]
pub struct CouplingParams {
    pub n_rows: u32,
    pub _pad0: u32,
    pub _pad1: u32,
    pub _pad2: u32,
}
const _: () = assert!(std::mem::size_of::<CouplingParams>() == 16);

/// C's block rows as the shader reads them: the row of each block row, offsets into the
/// blocks, the blocks' columns, and each block's three rows as lanes (lane 3 zero).
#[derive(Clone, Debug, Default)]
pub struct BlockRows {
    pub rows: Vec<u32>,
    pub indptr: Vec<u32>,
    pub cols: Vec<u32>,
    pub blocks: Vec<[f64; 4]>,
}

impl BlockRows {
    /// The block rows of `c`.
    pub fn of(c: &crate::fit::rotated::Coupling) -> BlockRows {
        let mut out = BlockRows {
            indptr: vec![0],
            ..Default::default()
        };
        for (row, cols, blocks) in c.block_rows() {
            out.rows.push(row as u32);
            out.cols.extend_from_slice(cols);
            for m in blocks {
                out.blocks.extend(m.map(|[a, b, c]| [a, b, c, 0.0]));
            }
            out.indptr.push(out.cols.len() as u32);
        }
        out
    }

    /// The uniform block of the shader.
    pub fn params(&self) -> CouplingParams {
        CouplingParams {
            n_rows: self.rows.len() as u32,
            ..Default::default()
        }
    }
}

/// One invocation per block row `i`.
pub fn coupling<T: Real>(
    params: &CouplingParams,
    rows: &[u32],
    indptr: &[u32],
    cols: &[u32],
    blocks: &[Vec4<T>],
    x: &[Vec4<T>],
    y: &mut [Vec4<T>],
) {
    for i in 0..params.n_rows as usize {
        let row = rows[i] as usize;
        let mut s = y[row];
        for k in indptr[i] as usize..indptr[i + 1] as usize {
            let v = x[cols[k] as usize];
            let (m0, m1, m2) = (blocks[3 * k], blocks[3 * k + 1], blocks[3 * k + 2]);
            s[0] += m0[0] * v[0] + m0[1] * v[1] + m0[2] * v[2];
            s[1] += m1[0] * v[0] + m1[1] * v[1] + m1[2] * v[2];
            s[2] += m2[0] * v[0] + m2[1] * v[1] + m2[2] * v[2];
        }
        y[row] = s;
    }
}
