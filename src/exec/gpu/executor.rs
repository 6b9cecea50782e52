//! The GPU [`Executor`]: the WGSL kernels on one device. Certification falls back to the CPU
//! where the device fails (counted in [`Executor::fallbacks`]); the CG solve, sampling and the
//! local derivatives return the device's error instead.

use super::GpuContext;
use super::jacobian_check::GpuCertifier;
use crate::energy::colored::{LocalDerivatives, LocalProblem};
use crate::energy::{EnergyKernel, KernelError};
use crate::exec::{Executor, ExecutorError};
use crate::fit::NormalMatrix;
use crate::fit::rotated::Coupling;
use crate::math::{BezierElements, BezierNet};
use crate::mesh::HighOrderMesh;
use crate::mesh::{LinearMesh, Topology};
use crate::solve::{CgError, CgInfo, CgParams};
use crate::validity::{Certifier, DetBounds};

/// The executor on `ctx`.
pub struct GpuExecutor<'a> {
    certifier: GpuCertifier<'a>,
}

impl<'a> GpuExecutor<'a> {
    pub fn new(ctx: &'a GpuContext) -> Self {
        GpuExecutor {
            certifier: GpuCertifier::new(ctx),
        }
    }

    fn ctx(&self) -> &'a GpuContext {
        self.certifier.ctx
    }
}

impl Certifier for GpuExecutor<'_> {
    fn certify(
        &self,
        dim: usize,
        elements: &[usize],
        net: &(dyn Fn(usize) -> BezierNet + Sync),
        max_depth: usize,
    ) -> Vec<DetBounds> {
        self.certifier.certify(dim, elements, net, max_depth)
    }
}

impl EnergyKernel for GpuExecutor<'_> {
    /// The `local_newton` kernel; a device failure is the kernel's error.
    fn local_derivatives(
        &self,
        dim: usize,
        problems: &[LocalProblem],
    ) -> Result<Option<Vec<LocalDerivatives>>, KernelError> {
        super::local_newton::local_newton(self.ctx(), dim, problems)
            .map(Some)
            .map_err(|e| KernelError(ExecutorError::from(e).to_string()))
    }
}

impl Executor for GpuExecutor<'_> {
    fn name(&self) -> &'static str {
        "gpu"
    }

    fn gpu(&self) -> Option<&GpuContext> {
        Some(self.ctx())
    }

    fn pcg(
        &self,
        k: NormalMatrix,
        b: &[[f64; 3]],
        x: &mut [[f64; 3]],
        params: &CgParams,
        progress: &mut dyn crate::solve::CgMonitor,
    ) -> Result<CgInfo, CgError> {
        super::cg::pcg(self.ctx(), &k, b, x, params, progress)
    }

    fn pcg_coupled(
        &self,
        k: NormalMatrix,
        c: &Coupling,
        b: &[[f64; 3]],
        x: &mut [[f64; 3]],
        params: &CgParams,
        progress: &mut dyn crate::solve::CgMonitor,
    ) -> Result<CgInfo, CgError> {
        super::cg::pcg_coupled(self.ctx(), &k, c, b, x, params, progress)
    }

    fn coupled_preconditioner(&self) -> crate::fit::rotated::OnK {
        // The device's coupled CG is preconditioned by K's diagonal, as its uncoupled one.
        crate::fit::rotated::OnK::Jacobi
    }

    fn sample(
        &self,
        source: &dyn BezierElements,
        mesh: &LinearMesh,
        topo: &Topology,
        p: usize,
    ) -> Result<HighOrderMesh, ExecutorError> {
        Ok(super::evaluate::sample(self.ctx(), source, mesh, topo, p)?)
    }

    fn fallbacks(&self) -> usize {
        self.certifier
            .fallbacks
            .load(std::sync::atomic::Ordering::Relaxed)
    }
}
