//! The CPU reference [`Executor`]: f64 throughout, in parallel with rayon.

use crate::energy::colored::{LocalDerivatives, LocalProblem};
use crate::energy::{CpuEnergyKernel, EnergyKernel, KernelError};
use crate::exec::{Executor, ExecutorError};
use crate::fit::NormalMatrix;
use crate::fit::rotated::{Coupling, OnK};
use crate::math::{BezierElements, BezierNet};
use crate::mesh::HighOrderMesh;
use crate::mesh::{LinearMesh, Topology};
use crate::solve::{CgError, CgInfo, CgParams};
use crate::validity::{Certifier, CpuCertifier, DetBounds};

/// The CPU reference executor.
pub struct CpuExecutor;

impl Certifier for CpuExecutor {
    fn certify(
        &self,
        dim: usize,
        elements: &[usize],
        net: &(dyn Fn(usize) -> BezierNet + Sync),
        max_depth: usize,
    ) -> Vec<DetBounds> {
        CpuCertifier.certify(dim, elements, net, max_depth)
    }
}

impl Executor for CpuExecutor {
    fn name(&self) -> &'static str {
        "cpu"
    }

    fn pcg(
        &self,
        k: NormalMatrix,
        b: &[[f64; 3]],
        x: &mut [[f64; 3]],
        params: &CgParams,
        progress: &mut dyn crate::solve::CgMonitor,
    ) -> Result<CgInfo, CgError> {
        k.pcg(b, x, params, progress)
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
        crate::fit::rotated::solve(&k, c, b, x, params, self.coupled_preconditioner(), progress)
    }

    fn coupled_preconditioner(&self) -> OnK {
        OnK::BlockJacobiPair
    }

    fn sample(
        &self,
        source: &dyn BezierElements,
        mesh: &LinearMesh,
        topo: &Topology,
        p: usize,
    ) -> Result<HighOrderMesh, ExecutorError> {
        Ok(crate::sample::sample(source, mesh, topo, p))
    }
}

impl EnergyKernel for CpuExecutor {
    fn local_derivatives(
        &self,
        dim: usize,
        problems: &[LocalProblem],
    ) -> Result<Option<Vec<LocalDerivatives>>, KernelError> {
        CpuEnergyKernel.local_derivatives(dim, problems)
    }
}
