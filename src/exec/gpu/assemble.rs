//! `shaders/assemble.wgsl`: the fit's normal matrix K summed on the device, row by row from
//! the element matrices, straight into the value buffers of a [`super::cg::GpuMatrix`]'s row
//! blocks. CPU twin: [`crate::exec::cpu::assemble`].
//!
//! The host keeps K's structure (row offsets, sorted columns) and the symbolic part of the
//! sums ([`RowSums`]): the element matrices (one per (pattern, weight mask) on regular
//! meshes; graded and constrained elements their own), each element's columns and each row's
//! incident elements in element order. Those go up instead of K's values: one invocation per
//! row adds row i of every incident element's matrix into the row, in element order, so in
//! f64 the values are the host assembly's bit for bit; in f32 each sum of at most a row's
//! incident elements' terms rounds once per addition ([`ASSEMBLE_TOL_F32`]).

use super::{GpuContext, GpuError, Precision, reals_to_bytes};
use crate::fit::assembly::{ElementTables, RowSums};

pub use crate::exec::cpu::assemble::AssembleParams;

pub const SOURCE: &str = include_str!("../../../shaders/assemble.wgsl");

/// Agreement of the f32 kernel's entries with the f64 assembly, relative to the sum of the
/// magnitudes of an entry's terms: each of at most 64 additions and the scaling round once,
/// and so does each term's conversion to f32.
pub const ASSEMBLE_TOL_F32: f64 = 2.0 * 66.0 * f32::EPSILON as f64;

/// The element tables and the row scaling on the device, shared by every row block.
pub struct DeviceTables {
    elements: wgpu::Buffer,
    elem_cols: wgpu::Buffer,
    mats: wgpu::Buffer,
    scale: wgpu::Buffer,
    local_bits: u32,
    pipeline: wgpu::ComputePipeline,
}

/// `bytes` in one binding, or why not.
fn fits(ctx: &GpuContext, what: &str, bytes: u64) -> Result<(), GpuError> {
    if bytes > ctx.max_binding() {
        return Err(GpuError::TooLarge(format!(
            "{what}: {bytes} bytes (binding limit {})",
            ctx.max_binding()
        )));
    }
    Ok(())
}

impl DeviceTables {
    /// Upload the element tables of `sums` and the scaling `scale` (none: 1).
    pub fn new(ctx: &GpuContext, sums: &RowSums, scale: Option<&[f64]>) -> Result<Self, GpuError> {
        let ElementTables {
            elements,
            elem_cols,
            mats,
            local_bits,
        } = sums.tables().map_err(GpuError::TooLarge)?;
        let sz = ctx.precision.size() as u64;
        fits(ctx, "element matrices", sz * mats.len() as u64)?;
        fits(ctx, "element columns", 4 * elem_cols.len() as u64)?;
        fits(ctx, "elements", 8 * elements.len() as u64)?;
        fits(ctx, "scaling", sz * sums.n() as u64)?;
        let ones = std::iter::repeat_n(1.0, sums.n());
        let scale = match scale {
            Some(d) => reals_to_bytes(ctx.precision, d.iter().copied()),
            None => reals_to_bytes(ctx.precision, ones),
        };
        Ok(DeviceTables {
            elements: ctx.storage("elements", bytemuck::cast_slice(&elements), false),
            elem_cols: ctx.storage("elem_cols", bytemuck::cast_slice(elem_cols), false),
            mats: ctx.storage(
                "element matrices",
                &reals_to_bytes(ctx.precision, mats.iter().copied()),
                false,
            ),
            scale: ctx.storage("scale", &scale, false),
            local_bits,
            pipeline: ctx.pipeline(SOURCE, "assemble"),
        })
    }

    /// Sum rows `r0..r1` of K into `data` (their block's values), given the block's row
    /// pointers `indptr` and columns `indices` on the device.
    pub fn sum_rows(
        &self,
        ctx: &GpuContext,
        sums: &RowSums,
        (r0, r1): (usize, usize),
        [indptr, indices, data]: [&wgpu::Buffer; 3],
    ) -> Result<(), GpuError> {
        let (inc_start, incidence) = sums.incidence(r0..r1, self.local_bits);
        fits(ctx, "incidence", 4 * incidence.len() as u64)?;
        let params = ctx.uniform(
            "assemble params",
            &AssembleParams {
                n_rows: (r1 - r0) as u32,
                row_base: r0 as u32,
                local_bits: self.local_bits,
                _pad: 0,
            },
        );
        let inc_start = ctx.storage("inc_start", bytemuck::cast_slice(&inc_start), false);
        let incidence = ctx.storage("incidence", bytemuck::cast_slice(&incidence), false);
        ctx.run_once(
            &self.pipeline,
            &[
                (0, &params),
                (1, indptr),
                (2, indices),
                (3, &inc_start),
                (4, &incidence),
                (5, &self.elements),
                (6, &self.elem_cols),
                (7, &self.mats),
                (8, &self.scale),
                (9, data),
            ],
            r1 - r0,
        );
        Ok(())
    }
}

/// Whether the element tables of `sums` (with the incidence and the scaling) are fewer
/// bytes at precision `p` than the `nnz` values they are summed into.
pub fn moves_less(p: Precision, sums: &RowSums, nnz: usize) -> bool {
    let sz = p.size();
    let [mats, cols, elements, incidence] = sums.device_entries();
    let tables = sz * mats + 4 * cols + 8 * elements + 4 * (incidence + sums.n()) + sz * sums.n();
    tables < sz * nnz
}

/// Whether `p` sums the same bits as the host (f64), so a device-summed K is the host's K.
pub fn exact(p: Precision) -> bool {
    matches!(p, Precision::F64)
}
