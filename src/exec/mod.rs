//! The execution floor, and its one CPU/GPU seam: an [`Executor`] certifies det J bounds (it
//! is a [`Certifier`]), solves the fit's normal equations by PCG, samples Lagrange nodes and
//! computes the energy's local derivatives (it is an [`EnergyKernel`]). [`CpuExecutor`]
//! ([`cpu`]: the reference, beside the CPU twins of the kernels) and [`GpuExecutor`] ([`gpu`]:
//! the WGSL kernels of `shaders/`) implement it. Stages take a `&dyn Executor` and never a GPU
//! context; the algorithms below take only the narrow traits they need.
//!
//! Invariants: both return the same kind of result (certified bounds, a CG solution to the
//! requested tolerance, nodes in the same order); a device failure is a typed error
//! ([`ExecutorError`], or [`CgError::Device`] from the solve), never a panic; where the GPU
//! executor hands work back to the CPU it counts it ([`Executor::fallbacks`]) and the report
//! says so.

pub mod cpu;
pub mod gpu;

use crate::energy::EnergyKernel;
use crate::exec::gpu::{Backend, GpuContext, GpuError};
use crate::fit::NormalMatrix;
use crate::fit::rotated::Coupling;
use crate::math::BezierElements;
use crate::mesh::HighOrderMesh;
use crate::mesh::{LinearMesh, Topology};
use crate::solve::{CgError, CgInfo, CgParams};
use crate::validity::Certifier;

pub use crate::exec::cpu::executor::CpuExecutor;
pub use crate::exec::gpu::executor::GpuExecutor;

/// A failure of an executor's work as the callers above the seam see it: they match on it or
/// print it, and never name a device type (the energy, for one, knows only its `EnergyKernel`).
#[derive(Debug, thiserror::Error)]
pub enum ExecutorError {
    /// The device failed (lost, out of memory, a mapping error); the message is the device's.
    #[error(transparent)]
    Device(#[from] GpuError),
}

/// Where the heavy work runs (see the module docs).
pub trait Executor: Certifier + EnergyKernel {
    /// `cpu` or `gpu`.
    fn name(&self) -> &'static str;

    /// The device, when this executor runs on one (for the report).
    fn gpu(&self) -> Option<&GpuContext> {
        None
    }

    /// Solve `k` x = `b` by preconditioned CG from `x`, telling `progress` every iteration
    /// (it may stop the solve: [`CgError::Cancelled`]). The solve owns `k`: the CPU's blocked
    /// solvers release it as they build their own form of it. The error is the solver seam's [`CgError`]: besides
    /// breakdowns it carries a device failure as [`CgError::Device`].
    fn pcg(
        &self,
        k: NormalMatrix,
        b: &[[f64; 3]],
        x: &mut [[f64; 3]],
        params: &CgParams,
        progress: &mut dyn crate::solve::CgMonitor,
    ) -> Result<CgInfo, CgError>;

    /// Solve the fit's coupled system across rotation seams, (`k` ⊗ I₃ + `c`) x = `b`, by the
    /// coupled CG (one recurrence over the three coordinates, [`crate::solve::pcg_coupled`])
    /// from `x`, preconditioned by K alone (⊗ I₃): on the CPU by K's block-Jacobi pair
    /// ([`crate::fit::rotated::solve`]), on a device by K's diagonal as its uncoupled CG
    /// ([`Self::coupled_preconditioner`]); `progress` sees every iteration on both. Errors as
    /// [`Self::pcg`].
    fn pcg_coupled(
        &self,
        k: NormalMatrix,
        c: &Coupling,
        b: &[[f64; 3]],
        x: &mut [[f64; 3]],
        params: &CgParams,
        progress: &mut dyn crate::solve::CgMonitor,
    ) -> Result<CgInfo, CgError>;

    /// What preconditions [`Self::pcg_coupled`]'s CG.
    fn coupled_preconditioner(&self) -> crate::fit::rotated::OnK;

    /// The order-`p` Lagrange nodes of `source`'s elements.
    fn sample(
        &self,
        source: &dyn BezierElements,
        mesh: &LinearMesh,
        topo: &Topology,
        p: usize,
    ) -> Result<HighOrderMesh, ExecutorError>;

    /// Batches the device failed and the CPU computed instead (0 on the CPU).
    fn fallbacks(&self) -> usize {
        0
    }
}

/// The executor of `backend`.
pub fn executor(backend: &Backend) -> Box<dyn Executor + '_> {
    match backend {
        Backend::Cpu => Box::new(CpuExecutor),
        Backend::Gpu(ctx) => Box::new(GpuExecutor::new(ctx)),
    }
}
