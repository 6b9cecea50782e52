//! The CG pieces on the GPU: `shaders/spmv.wgsl` (CSR operator on three right-hand sides),
//! `shaders/dot.wgsl` (first reduction stage), `shaders/cg.wgsl` (second stage with α/β, and
//! the vector updates). CPU twins: [`crate::exec::cpu::spmv`], [`crate::exec::cpu::dot`], [`crate::exec::cpu::cg`].
//!
//! [`GpuOperator`] is a [`LinOp`] (one SpMV per `apply`, with an upload and a read-back), so
//! the CPU's CG loop can run on it; [`pcg`] keeps the whole iteration on the GPU: every scalar
//! lives in a GPU buffer, [`CG_BATCH`] iterations are encoded per submit, and only the state
//! and the scalars (a few hundred bytes) are read back per batch. In f32 it is wrapped in
//! iterative refinement: the residual b − A x is recomputed in f64 on the CPU, and the GPU
//! solves for the correction (displacement unknowns), so the f64 tolerance is met although
//! the GPU's arithmetic is f32. The GPU solver is point-Jacobi PCG whatever
//! `CgParams::preconditioner` asks for (the block-Jacobi triangular solves are sequential per
//! aggregate and are not ported to WGSL). A matrix whose values are not summed yet
//! ([`NormalMatrix::unsummed`]) gets them from `shaders/assemble.wgsl` on the device
//! ([`super::assemble`]). In f64 the refinement's residuals are products on the device, so
//! the host never sums them.
//!
//! [`pcg_coupled`] solves the fit's coupled system across rotation seams, (K ⊗ I₃ + C) x = b
//! ([`crate::fit::rotated`]), with the same kernels and buffers: each product is spmv.wgsl's
//! K p followed by `shaders/coupling.wgsl`'s C p over C's block rows (CPU twin
//! [`crate::exec::cpu::coupling`]), and cg.wgsl's finalisers run one recurrence over the
//! three coordinates (`CgKernelParams::coupled`: the sums of the three lanes, one α and β),
//! as the CPU's [`crate::solve::pcg_coupled`] does; preconditioned by K's diagonal ⊗ I₃ (C's
//! diagonal blocks vanish), the uncoupled solver's point Jacobi. Its f32 refinement scales
//! the three coordinates of the residual by one norm (a coupled system is not solved
//! coordinate by coordinate).
//!
//! [`pcg`] does not run the CPU solvers' loop ([`crate::solve::iterate`]), whose steps return
//! their sums to the host after every pass: here the vectors stay on the device, and α, β,
//! which components still run and the breakdown test are decided by the kernels
//! (`finalize_alpha`, `finalize_beta`) in the device's precision, [`CG_BATCH`] iterations per
//! submit with one read-back of the state. Driving the iteration from the host would cost
//! two synchronous read-backs per iteration (pᵀAp; rᵀz with rᵀr) instead of one per batch,
//! and in f32 would compute α and β in f64 from f32 sums, a different solver. What the two
//! share: the stopping rule and its targets, the iteration record and the final error
//! ([`Stopping`]), the f32 refinement's f64 residual (`solve::residual`), and the step arithmetic: the
//! kernels' CPU twin computes α and β with the CPU loop's [`crate::solve::step_lengths`] and
//! [`crate::solve::direction_weights`].

use super::{
    Bound, GpuContext, GpuError, ITEM_WORKGROUP, Precision, bytes_to_reals, groups, reals_to_bytes,
};
pub use crate::exec::cpu::cg::{CgKernelParams, CgState};
pub use crate::exec::cpu::coupling::{BlockRows, CouplingParams};
pub use crate::exec::cpu::dot::DotParams;
pub use crate::exec::cpu::spmv::SpmvParams;
use crate::fit::NormalMatrix;
use crate::fit::rotated::Coupling;
use crate::solve::{CgError, CgInfo, CgParams, LinOp, Stopping, residual};

pub const SPMV_SOURCE: &str = include_str!("../../../shaders/spmv.wgsl");
pub const DOT_SOURCE: &str = include_str!("../../../shaders/dot.wgsl");
pub const CG_SOURCE: &str = include_str!("../../../shaders/cg.wgsl");
pub const COUPLING_SOURCE: &str = include_str!("../../../shaders/coupling.wgsl");

/// Iterations encoded per submit (one read-back of a few bytes per batch).
pub const CG_BATCH: usize = 10;
/// Workgroups of the first reduction stage (the second stage is one workgroup of 256).
pub const DOT_WORKGROUPS: u32 = 64;
/// f32 inner solves reduce the residual by this factor per refinement round: the recursively
/// updated f32 residual is not trustworthy much below ~1e-5 of its start.
pub const F32_INNER_REDUCTION: f64 = 1e-3;
/// Refinement rounds at most.
pub const MAX_REFINEMENTS: usize = 60;
/// Agreement of an f32 SpMV with the f64 one, relative to Σ|a_ij||x_j| per row: each product
/// and sum is rounded once (rows have ≤ ~130 entries, so 2·130·ε/2 bounds the sum; the
/// inputs' own rounding adds 2ε).
pub const SPMV_TOL_F32: f64 = 160.0 * f32::EPSILON as f64;
/// The same for f64 kernels.
pub const SPMV_TOL_F64: f64 = 160.0 * f64::EPSILON;

/// Scalars of cg.wgsl: rz, rr, target², α, β, pᵀAp, each a vec4.
pub const SCALARS: usize = 6 * 4;

/// A row block of the matrix, small enough for one binding.
struct Block {
    params: wgpu::Buffer,
    indptr: wgpu::Buffer,
    indices: wgpu::Buffer,
    data: wgpu::Buffer,
    n_rows: usize,
    nnz: usize,
}

/// A CSR matrix on the GPU, split into row blocks whose index and value arrays each fit one
/// storage binding.
pub struct GpuMatrix {
    pub n: usize,
    blocks: Vec<Block>,
    diag: Vec<f64>,
}

impl GpuMatrix {
    /// `a` on the device: its values uploaded, or, when they are not summed yet
    /// ([`NormalMatrix::unsummed`]), summed on the device by `assemble.wgsl` from the element
    /// tables. The host sums and uploads them instead where the tables would move more bytes
    /// than the values ([`super::assemble::moves_less`]: graded knots, whose elements each have
    /// their own 27 × 27 matrix) or the device cannot hold them.
    pub fn new(ctx: &GpuContext, a: &NormalMatrix) -> Result<GpuMatrix, GpuError> {
        if let Some((sums, scale)) = a.unsummed()
            && super::assemble::moves_less(ctx.precision, sums, a.indices().len())
        {
            match super::assemble::DeviceTables::new(ctx, sums, scale) {
                Ok(tables) => match Self::build(ctx, a, Some((&tables, sums))) {
                    Err(GpuError::TooLarge(_)) => {}
                    built => return built,
                },
                Err(GpuError::TooLarge(_)) => {}
                Err(e) => return Err(e),
            }
        }
        Self::build(ctx, a, None)
    }

    /// `a`, whose values are not summed yet, with its values summed on the device whatever
    /// the bytes (`GpuError::TooLarge` where the device cannot hold the element tables).
    pub fn summed_on_device(ctx: &GpuContext, a: &NormalMatrix) -> Result<GpuMatrix, GpuError> {
        let Some((sums, scale)) = a.unsummed() else {
            return Err(GpuError::TooLarge("the values are summed already".into()));
        };
        let tables = super::assemble::DeviceTables::new(ctx, sums, scale)?;
        Self::build(ctx, a, Some((&tables, sums)))
    }

    /// The values of every row as the device holds them (read back, row by row).
    pub fn values(&self, ctx: &GpuContext) -> Result<Vec<f64>, GpuError> {
        let mut out = Vec::new();
        for b in &self.blocks {
            let bytes = b.data.size();
            let reals = bytes_to_reals(ctx.precision, &ctx.read_back(&b.data, bytes)?);
            out.extend_from_slice(&reals[..b.nnz]);
        }
        Ok(out)
    }

    /// The row blocks of `a`, their values summed by `device` or uploaded.
    fn build(
        ctx: &GpuContext,
        a: &NormalMatrix,
        device: Option<(
            &super::assemble::DeviceTables,
            &crate::fit::assembly::RowSums,
        )>,
    ) -> Result<GpuMatrix, GpuError> {
        let sz = ctx.precision.size() as u64;
        let vec_bytes = 4 * sz * a.n() as u64;
        if vec_bytes > ctx.max_binding() || a.n() > ctx.max_workgroups() as usize * ITEM_WORKGROUP {
            return Err(GpuError::TooLarge(format!(
                "{} unknowns need {vec_bytes} bytes per vector (binding limit {})",
                a.n(),
                ctx.max_binding()
            )));
        }
        let max_nnz = (ctx.max_binding() / sz.max(4)) as usize;
        let mut blocks = Vec::new();
        let mut r0 = 0;
        while r0 < a.n() {
            let mut r1 = r0 + 1;
            while r1 < a.n() && a.indptr()[r1 + 1] - a.indptr()[r0] <= max_nnz {
                r1 += 1;
            }
            let (k0, k1) = (a.indptr()[r0], a.indptr()[r1]);
            if k1 - k0 > max_nnz {
                return Err(GpuError::TooLarge(format!(
                    "row {r0} has {} entries",
                    k1 - k0
                )));
            }
            let indptr: Vec<u32> = a.indptr()[r0..=r1]
                .iter()
                .map(|&k| (k - k0) as u32)
                .collect();
            let indptr = ctx.storage("indptr", bytemuck::cast_slice(&indptr), false);
            let indices = ctx.storage("indices", bytemuck::cast_slice(&a.indices()[k0..k1]), false);
            let data = match device {
                Some((tables, sums)) => {
                    let data = ctx.storage_zeroed("data", sz * (k1 - k0) as u64);
                    tables.sum_rows(ctx, sums, (r0, r1), [&indptr, &indices, &data])?;
                    data
                }
                None => ctx.storage(
                    "data",
                    &reals_to_bytes(ctx.precision, a.data()[k0..k1].iter().copied()),
                    false,
                ),
            };
            blocks.push(Block {
                params: ctx.uniform(
                    "spmv params",
                    &SpmvParams {
                        n_rows: (r1 - r0) as u32,
                        row_base: r0 as u32,
                        _pad0: 0,
                        _pad1: 0,
                    },
                ),
                indptr,
                indices,
                data,
                n_rows: r1 - r0,
                nnz: k1 - k0,
            });
            r0 = r1;
        }
        Ok(GpuMatrix {
            n: a.n(),
            blocks,
            diag: a.diagonal(),
        })
    }

    /// Number of row blocks (1 unless the matrix exceeds one binding).
    pub fn n_blocks(&self) -> usize {
        self.blocks.len()
    }

    /// Bind groups of y = A x for every block.
    fn bind(
        &self,
        ctx: &GpuContext,
        pipeline: &wgpu::ComputePipeline,
        x: &wgpu::Buffer,
        y: &wgpu::Buffer,
    ) -> Vec<Bound> {
        self.blocks
            .iter()
            .map(|b| {
                ctx.bind(
                    pipeline,
                    &[
                        (0, &b.params),
                        (1, &b.indptr),
                        (2, &b.indices),
                        (3, &b.data),
                        (4, x),
                        (5, y),
                    ],
                )
            })
            .collect()
    }

    fn encode(
        &self,
        ctx: &GpuContext,
        pass: &mut wgpu::ComputePass<'_>,
        pipeline: &wgpu::ComputePipeline,
        binds: &[Bound],
    ) {
        for (b, g) in self.blocks.iter().zip(binds) {
            ctx.dispatch(pass, pipeline, g, groups(b.n_rows, ITEM_WORKGROUP));
        }
    }
}

/// The coupling C's block rows on the device, for `coupling.wgsl` (y += C x after spmv.wgsl's
/// y = K x).
pub struct GpuCoupling {
    params: wgpu::Buffer,
    rows: wgpu::Buffer,
    indptr: wgpu::Buffer,
    cols: wgpu::Buffer,
    blocks: wgpu::Buffer,
    n_rows: usize,
    pipeline: wgpu::ComputePipeline,
}

impl GpuCoupling {
    /// `c` uploaded ([`BlockRows`]); `GpuError::TooLarge` where its blocks exceed a binding.
    pub fn new(ctx: &GpuContext, c: &Coupling) -> Result<GpuCoupling, GpuError> {
        let rows = BlockRows::of(c);
        let bytes = 4 * ctx.precision.size() as u64 * rows.blocks.len() as u64;
        if bytes > ctx.max_binding()
            || rows.rows.len() > ctx.max_workgroups() as usize * ITEM_WORKGROUP
        {
            return Err(GpuError::TooLarge(format!(
                "the coupling's {} blocks need {bytes} bytes (binding limit {})",
                rows.cols.len(),
                ctx.max_binding()
            )));
        }
        Ok(GpuCoupling {
            params: ctx.uniform("coupling params", &rows.params()),
            rows: ctx.storage("coupling rows", bytemuck::cast_slice(&rows.rows), false),
            indptr: ctx.storage("coupling indptr", bytemuck::cast_slice(&rows.indptr), false),
            cols: ctx.storage("coupling cols", bytemuck::cast_slice(&rows.cols), false),
            blocks: ctx.storage(
                "coupling blocks",
                &reals_to_bytes(ctx.precision, rows.blocks.iter().flatten().copied()),
                false,
            ),
            n_rows: rows.rows.len(),
            pipeline: ctx.pipeline(COUPLING_SOURCE, "coupling"),
        })
    }

    /// The bind group of y += C x.
    fn bind(&self, ctx: &GpuContext, x: &wgpu::Buffer, y: &wgpu::Buffer) -> Bound {
        ctx.bind(
            &self.pipeline,
            &[
                (0, &self.params),
                (1, &self.rows),
                (2, &self.indptr),
                (3, &self.cols),
                (4, &self.blocks),
                (5, x),
                (6, y),
            ],
        )
    }

    fn encode(&self, ctx: &GpuContext, pass: &mut wgpu::ComputePass<'_>, bound: &Bound) {
        ctx.dispatch(
            pass,
            &self.pipeline,
            bound,
            groups(self.n_rows, ITEM_WORKGROUP),
        );
    }
}

/// y = A x on the device, x uploaded and y read back: spmv.wgsl's K x (`spmv` its pipeline),
/// then coupling.wgsl's C x where `coupling` is given (A = K ⊗ I₃ + C), in one pass.
fn apply_once(
    ctx: &GpuContext,
    matrix: &GpuMatrix,
    spmv: &wgpu::ComputePipeline,
    coupling: Option<&GpuCoupling>,
    x: &[[f64; 3]],
) -> Result<Vec<[f64; 3]>, GpuError> {
    let bytes = 4 * ctx.precision.size() as u64 * matrix.n as u64;
    let xb = ctx.storage("x", &vec4_bytes(ctx.precision, x), false);
    let yb = ctx.storage_zeroed("y", bytes);
    let binds = matrix.bind(ctx, spmv, &xb, &yb);
    let coupled = coupling.map(|c| (c, c.bind(ctx, &xb, &yb)));
    let mut enc = ctx.device.create_command_encoder(&Default::default());
    {
        let mut pass = enc.begin_compute_pass(&Default::default());
        matrix.encode(ctx, &mut pass, spmv, &binds);
        if let Some((c, bound)) = &coupled {
            c.encode(ctx, &mut pass, bound);
        }
    }
    ctx.submit(enc);
    Ok(from_vec4(&bytes_to_reals(
        ctx.precision,
        &ctx.read_back(&yb, bytes)?,
    )))
}

/// Vectors of three components as vec4 lanes at precision `p`.
fn vec4_bytes(p: Precision, v: &[[f64; 3]]) -> Vec<u8> {
    reals_to_bytes(p, v.iter().flat_map(|x| [x[0], x[1], x[2], 0.0]))
}

fn from_vec4(v: &[f64]) -> Vec<[f64; 3]> {
    v.chunks_exact(4).map(|c| [c[0], c[1], c[2]]).collect()
}

/// The normal matrix on the GPU as a [`LinOp`]: `apply` uploads x, runs spmv.wgsl, reads y.
///
/// A device failure inside [`LinOp::apply`] (which cannot return an error) does not panic: the
/// first error is kept, `y` is filled with NaN (so a CG loop on the operator stops at its next
/// curvature test instead of iterating on garbage), later applications do not touch the device,
/// and [`GpuOperator::pcg`] / [`GpuOperator::device_error`] turn it into
/// [`CgError::Device`].
pub struct GpuOperator<'a> {
    ctx: &'a GpuContext,
    matrix: GpuMatrix,
    pipeline: wgpu::ComputePipeline,
    /// C of the coupled system K ⊗ I₃ + C, applied after K ([`GpuOperator::coupled`]).
    coupling: Option<GpuCoupling>,
    failed: std::sync::Mutex<Option<GpuError>>,
}

impl<'a> GpuOperator<'a> {
    pub fn new(ctx: &'a GpuContext, a: &NormalMatrix) -> Result<Self, GpuError> {
        Ok(GpuOperator {
            ctx,
            matrix: GpuMatrix::new(ctx, a)?,
            pipeline: ctx.pipeline(SPMV_SOURCE, "spmv"),
            coupling: None,
            failed: std::sync::Mutex::new(None),
        })
    }

    /// The coupled operator K ⊗ I₃ + C of the fit across rotation seams: spmv.wgsl, then
    /// coupling.wgsl.
    pub fn coupled(ctx: &'a GpuContext, a: &NormalMatrix, c: &Coupling) -> Result<Self, GpuError> {
        Ok(GpuOperator {
            coupling: Some(GpuCoupling::new(ctx, c)?),
            ..Self::new(ctx, a)?
        })
    }

    pub fn try_apply(&self, x: &[[f64; 3]]) -> Result<Vec<[f64; 3]>, GpuError> {
        apply_once(
            self.ctx,
            &self.matrix,
            &self.pipeline,
            self.coupling.as_ref(),
            x,
        )
    }

    pub fn n_blocks(&self) -> usize {
        self.matrix.n_blocks()
    }

    /// The device failure an earlier [`LinOp::apply`] met, as a solver error (`Ok` if none).
    pub fn device_error(&self) -> Result<(), CgError> {
        match &*self.failed.lock().unwrap_or_else(|e| e.into_inner()) {
            Some(e) => Err(CgError::Device(e.to_string())),
            None => Ok(()),
        }
    }

    /// Record a device failure (the first one is kept).
    fn fail(&self, e: GpuError) {
        let mut slot = self.failed.lock().unwrap_or_else(|e| e.into_inner());
        slot.get_or_insert(e);
    }

    /// [`crate::solve::pcg`] on this operator; a device failure during the solve is
    /// [`CgError::Device`], whatever the loop made of the NaN it saw.
    pub fn pcg(
        &self,
        b: &[[f64; 3]],
        x: &mut [[f64; 3]],
        params: &CgParams,
        progress: impl crate::solve::CgMonitor,
    ) -> Result<CgInfo, CgError> {
        let r = crate::solve::pcg(self, b, x, params, progress);
        self.device_error()?;
        r
    }
}

impl LinOp for GpuOperator<'_> {
    fn nrows(&self) -> usize {
        self.matrix.n
    }
    /// y = A x on the device; on a device failure y is NaN and the error is kept (see the
    /// type's docs).
    fn apply(&self, x: &[[f64; 3]], y: &mut [[f64; 3]]) {
        let result = if self.device_error().is_err() {
            None
        } else {
            self.try_apply(x).map_err(|e| self.fail(e)).ok()
        };
        match result {
            Some(r) => y.copy_from_slice(&r),
            None => y.fill([f64::NAN; 3]),
        }
    }
    fn diagonal(&self) -> Vec<f64> {
        self.matrix.diag.clone()
    }
}

fn dot3(a: &[[f64; 3]], b: &[[f64; 3]]) -> [f64; 3] {
    let mut s = [0.0; 3];
    for (x, y) in a.iter().zip(b) {
        for k in 0..3 {
            s[k] += x[k] * y[k];
        }
    }
    s
}

/// The pipelines, buffers and bind groups of one GPU CG solve: everything that does not
/// change between refinement rounds.
struct CgKernels<'c> {
    ctx: &'c GpuContext,
    n: usize,
    matrix: GpuMatrix,
    pipelines: [wgpu::ComputePipeline; 6],
    /// x (the inner correction d), r, z, p, Ap, 1/diag, partials, scalars, state.
    buffers: [wgpu::Buffer; 9],
    spmv_binds: Vec<Bound>,
    /// C and its bind group of Ap += C p, for the coupled system.
    coupling: Option<(GpuCoupling, Bound)>,
    dot_pap: Bound,
    dot_rz: Bound,
    staging: wgpu::Buffer,
}

impl<'c> CgKernels<'c> {
    fn new(
        ctx: &'c GpuContext,
        a: &NormalMatrix,
        c: Option<&Coupling>,
        inv: &[f64],
    ) -> Result<Self, GpuError> {
        let (n, prec) = (a.n(), ctx.precision);
        let sz = prec.size() as u64;
        let vbytes = 4 * sz * n as u64;
        let matrix = GpuMatrix::new(ctx, a)?;
        let pipelines = [
            ctx.pipeline(SPMV_SOURCE, "spmv"),
            ctx.pipeline(DOT_SOURCE, "dot_partial"),
            ctx.pipeline(CG_SOURCE, "finalize_alpha"),
            ctx.pipeline(CG_SOURCE, "update_xr"),
            ctx.pipeline(CG_SOURCE, "finalize_beta"),
            ctx.pipeline(CG_SOURCE, "update_p"),
        ];
        let buffers = [
            ctx.storage_zeroed("x", vbytes),
            ctx.storage_zeroed("r", vbytes),
            ctx.storage_zeroed("z", vbytes),
            ctx.storage_zeroed("p", vbytes),
            ctx.storage_zeroed("ap", vbytes),
            ctx.storage(
                "inv_diag",
                &reals_to_bytes(prec, inv.iter().copied()),
                false,
            ),
            ctx.storage_zeroed("partials", 2 * 4 * sz * DOT_WORKGROUPS as u64),
            ctx.storage_zeroed("scalars", SCALARS as u64 * sz),
            ctx.storage_zeroed("state", 16),
        ];
        let [_, r, z, p, ap, _, partials, _, _] = &buffers;
        let dot_params = ctx.uniform(
            "dot params",
            &DotParams {
                n: n as u32,
                ..Default::default()
            },
        );
        let dot = &pipelines[1];
        let spmv_binds = matrix.bind(ctx, &pipelines[0], p, ap);
        let coupling = match c {
            Some(c) => {
                let c = GpuCoupling::new(ctx, c)?;
                let bound = c.bind(ctx, p, ap);
                Some((c, bound))
            }
            None => None,
        };
        let dot_pap = ctx.bind(dot, &[(0, &dot_params), (1, p), (2, ap), (3, partials)]);
        let dot_rz = ctx.bind(dot, &[(0, &dot_params), (1, r), (2, z), (3, partials)]);
        let staging = ctx.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("cg state"),
            size: 16 + SCALARS as u64 * sz,
            usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        Ok(CgKernels {
            ctx,
            n,
            matrix,
            pipelines,
            buffers,
            spmv_binds,
            coupling,
            dot_pap,
            dot_rz,
            staging,
        })
    }

    /// One inner solve A d = `res` from d = 0 (z = p = `zv`, scalars `sc`), in batches of
    /// [`CG_BATCH`] iterations; `batch` sees the state and scalars after each batch and may stop
    /// the solve with an error. Returns the final state and d.
    fn solve(
        &self,
        res: &[[f64; 3]],
        zv: &[[f64; 3]],
        sc: Vec<f64>,
        max_iters: u32,
        mut batch: impl FnMut(&CgState, &[f64]) -> Result<(), CgError>,
    ) -> Result<(CgState, Vec<[f64; 3]>), CgError> {
        let dev = |e: GpuError| CgError::Device(e.to_string());
        let (ctx, n, prec) = (self.ctx, self.n, self.ctx.precision);
        let sz = prec.size() as u64;
        let vbytes = 4 * sz * n as u64;
        let [xd, r, z, p, ap, invb, partials, scalars, state] = &self.buffers;
        let [_, _, fin_a, upd_xr, fin_b, upd_p] = &self.pipelines;
        ctx.write(xd, &vec![0u8; vbytes as usize]);
        ctx.write(r, &vec4_bytes(prec, res));
        ctx.write(z, &vec4_bytes(prec, zv));
        ctx.write(p, &vec4_bytes(prec, zv));
        ctx.write(scalars, &reals_to_bytes(prec, sc.into_iter()));
        ctx.write(state, bytemuck::bytes_of(&CgState::default()));
        let cgp = ctx.uniform(
            "cg params",
            &CgKernelParams {
                n: n as u32,
                n_partials: DOT_WORKGROUPS,
                max_iters,
                coupled: u32::from(self.coupling.is_some()),
            },
        );
        let fa = ctx.bind(fin_a, &[(0, &cgp), (1, scalars), (2, state), (3, partials)]);
        let fb = ctx.bind(fin_b, &[(0, &cgp), (1, scalars), (2, state), (3, partials)]);
        let uxr = ctx.bind(
            upd_xr,
            &[
                (0, &cgp),
                (1, scalars),
                (4, xd),
                (5, r),
                (6, z),
                (7, p),
                (8, ap),
                (9, invb),
            ],
        );
        let up = ctx.bind(upd_p, &[(0, &cgp), (1, scalars), (6, z), (7, p)]);
        let st = loop {
            let mut enc = ctx.device.create_command_encoder(&Default::default());
            {
                let mut pass = enc.begin_compute_pass(&Default::default());
                for _ in 0..CG_BATCH {
                    self.encode_iteration(&mut pass, [&fa, &uxr, &fb, &up]);
                }
            }
            enc.copy_buffer_to_buffer(state, 0, &self.staging, 0, 16);
            enc.copy_buffer_to_buffer(scalars, 0, &self.staging, 16, SCALARS as u64 * sz);
            ctx.submit(enc);
            let bytes = ctx.map_read(&self.staging).map_err(dev)?;
            let st: CgState = *bytemuck::from_bytes(&bytes[..16]);
            batch(&st, &bytes_to_reals(prec, &bytes[16..]))?;
            if st.done != 0 {
                break st;
            }
        };
        let d = from_vec4(&bytes_to_reals(
            prec,
            &ctx.read_back(xd, vbytes).map_err(dev)?,
        ));
        Ok((st, d))
    }

    /// A x on the device (x uploaded, A x read back; A = K ⊗ I₃ + C when coupled).
    fn product(&self, x: &[[f64; 3]]) -> Result<Vec<[f64; 3]>, GpuError> {
        let coupling = self.coupling.as_ref().map(|(c, _)| c);
        apply_once(self.ctx, &self.matrix, &self.pipelines[0], coupling, x)
    }

    /// r = b − A x in f64 (A = K ⊗ I₃ + C when `c` is given): in f64 A x on the device
    /// (whoever summed K's values: the host need not hold them, and the iterates do not
    /// depend on where they were summed; from x = 0, r = b without a product), in f32 on the
    /// host.
    fn residual(
        &self,
        (a, c): (&NormalMatrix, Option<&Coupling>),
        b: &[[f64; 3]],
        x: &[[f64; 3]],
        r: &mut [[f64; 3]],
    ) -> Result<(), CgError> {
        if !super::assemble::exact(self.ctx.precision) {
            let mut apply = |v: &[[f64; 3]], y: &mut [[f64; 3]]| {
                a.apply(v, y);
                if let Some(c) = c {
                    c.apply_add(v, y);
                }
            };
            residual(&mut apply, b, x, r);
        } else if x.iter().all(|v| *v == [0.0; 3]) {
            r.copy_from_slice(b);
        } else {
            let ax = self
                .product(x)
                .map_err(|e| CgError::Device(e.to_string()))?;
            residual(&mut |_, y| y.copy_from_slice(&ax), b, x, r);
        }
        Ok(())
    }

    /// One CG iteration: Ap, pᵀAp, α and the x/r/z update, rᵀz, β and the p update.
    fn encode_iteration(&self, pass: &mut wgpu::ComputePass<'_>, binds: [&Bound; 4]) {
        let [spmv, dot, fin_a, upd_xr, fin_b, upd_p] = &self.pipelines;
        let [fa, uxr, fb, up] = binds;
        let lanes = groups(self.n, ITEM_WORKGROUP);
        self.matrix.encode(self.ctx, pass, spmv, &self.spmv_binds);
        if let Some((c, bound)) = &self.coupling {
            c.encode(self.ctx, pass, bound);
        }
        for (pipeline, bind, groups) in [
            (dot, &self.dot_pap, DOT_WORKGROUPS),
            (fin_a, fa, 1),
            (upd_xr, uxr, lanes),
            (dot, &self.dot_rz, DOT_WORKGROUPS),
            (fin_b, fb, 1),
            (upd_p, up, lanes),
        ] {
            self.ctx.dispatch(pass, pipeline, bind, groups);
        }
    }
}

/// Jacobi-PCG for `a` x = b with the iteration on the GPU (see the module docs). Same
/// contract as [`crate::solve::pcg`]; a device failure is [`CgError::Device`].
pub fn pcg(
    ctx: &GpuContext,
    a: &NormalMatrix,
    b: &[[f64; 3]],
    x: &mut [[f64; 3]],
    params: &CgParams,
    progress: impl crate::solve::CgMonitor,
) -> Result<CgInfo, CgError> {
    solve_on_device(ctx, (a, None), b, x, params, progress)
}

/// The coupled CG for (`a` ⊗ I₃ + `c`) x = b with the iteration on the GPU, preconditioned by
/// `a`'s diagonal ⊗ I₃ (see the module docs): the recurrence, stopping rule and iterates of
/// [`crate::solve::pcg_coupled`] with [`crate::fit::rotated::OnK::Jacobi`], to the device's
/// rounding. A device failure is [`CgError::Device`].
pub fn pcg_coupled(
    ctx: &GpuContext,
    a: &NormalMatrix,
    c: &Coupling,
    b: &[[f64; 3]],
    x: &mut [[f64; 3]],
    params: &CgParams,
    progress: impl crate::solve::CgMonitor,
) -> Result<CgInfo, CgError> {
    solve_on_device(ctx, (a, Some(c)), b, x, params, progress)
}

/// [`pcg`] (`c` None) or [`pcg_coupled`].
fn solve_on_device(
    ctx: &GpuContext,
    (a, c): (&NormalMatrix, Option<&Coupling>),
    b: &[[f64; 3]],
    x: &mut [[f64; 3]],
    params: &CgParams,
    mut progress: impl crate::solve::CgMonitor,
) -> Result<CgInfo, CgError> {
    let n = a.n();
    assert_eq!(b.len(), n);
    assert_eq!(x.len(), n);
    let diag = a.diagonal();
    if let Some((row, &value)) = diag.iter().enumerate().find(|(_, d)| !(**d > 0.0)) {
        return Err(CgError::BadDiagonal { row, value });
    }
    let inv: Vec<f64> = diag.iter().map(|d| 1.0 / d).collect();
    let kernels = CgKernels::new(ctx, a, c, &inv).map_err(|e| CgError::Device(e.to_string()))?;
    // The coupled recurrence's sums are over the three coordinates, in the first component
    // (the CPU's `solve::Coupled`), the other two converged from the start.
    let coupled = c.is_some();
    let sums = |d: [f64; 3]| {
        if coupled {
            [d[0] + d[1] + d[2], 0.0, 0.0]
        } else {
            d
        }
    };
    let stop = Stopping::new(sums(dot3(b, b)).map(f64::sqrt), params);
    let rel = |rr: [f64; 3]| stop.rel(rr);
    let inner_reduction = match ctx.precision {
        Precision::F32 => F32_INNER_REDUCTION,
        Precision::F64 => 0.0,
    };
    let mut total = 0usize;
    let mut res = vec![[0.0; 3]; n];
    for _round in 0..MAX_REFINEMENTS {
        // f64 residual of the current iterate.
        kernels.residual((a, c), b, x, &mut res)?;
        let rr = sums(dot3(&res, &res));
        if stop.converged(rr) {
            return Ok(CgInfo {
                iterations: total,
                rel_residual: rel(rr),
            });
        }
        if total >= params.max_iters {
            break;
        }
        // Inner problem A d = res / s from d = 0, each component scaled by its residual norm
        // s_k (the components have separate recurrences, so this is exact; coupled, all three
        // by the one norm) so that f32 sees O(1) values: no underflow of squared norms when b
        // is tiny.
        let norm = |k: usize| if rr[k] > 0.0 { rr[k].sqrt() } else { 1.0 };
        let scale: [f64; 3] = std::array::from_fn(|k| norm(if coupled { 0 } else { k }));
        for r in res.iter_mut() {
            for k in 0..3 {
                r[k] /= scale[k];
            }
        }
        let zv: Vec<[f64; 3]> = res
            .iter()
            .zip(&inv)
            .map(|(r, d)| r.map(|v| v * d))
            .collect();
        let rz = sums(dot3(&res, &zv));
        let rr_scaled = sums(dot3(&res, &res));
        let mut sc = vec![0.0f64; SCALARS];
        for k in 0..3 {
            sc[k] = rz[k];
            sc[4 + k] = rr_scaled[k];
            // Converged components get target² = f32::MAX: never active.
            sc[8 + k] = if !stop.running(rr, k) {
                f32::MAX as f64
            } else {
                (stop.target[k] / scale[k]).max(inner_reduction).powi(2)
            };
        }
        let max_iters = (params.max_iters - total).min(u32::MAX as usize) as u32;
        let lanes = if coupled { 1 } else { 3 };
        let (st, d) = kernels.solve(&res, &zv, sc, max_iters, |st, sc| {
            if st.breakdown > 0 {
                return Err(CgError::NotPositiveDefinite {
                    iteration: total + st.breakdown as usize - 1,
                    curvature: (0..lanes).map(|k| sc[20 + k]).fold(f64::INFINITY, f64::min),
                });
            }
            let rr_now: [f64; 3] = std::array::from_fn(|k| sc[4 + k] * scale[k] * scale[k]);
            stop.record(&mut progress, total + st.iterations as usize, rr_now)
        })?;
        for (x, d) in x.iter_mut().zip(&d) {
            for k in 0..3 {
                x[k] += d[k] * scale[k];
            }
        }
        if st.iterations == 0 {
            // No progress possible at this precision.
            break;
        }
        total += st.iterations as usize;
    }
    // The final iterate's residual in f64.
    kernels.residual((a, c), b, x, &mut res)?;
    let rr = sums(dot3(&res, &res));
    if stop.converged(rr) {
        return Ok(CgInfo {
            iterations: total,
            rel_residual: rel(rr),
        });
    }
    Err(stop.no_convergence(total, rr))
}
