//! The fit's normal equations summed over a subset of the elements: one rank's share of
//! K C = F in the distributed fit (`crate::distributed`).
//!
//! Input: the spline space, the mesh and its topology, the fit's parameters and smooth
//! targets, and the elements of the share. Output: K_s = Σ_{e ∈ share} E_eᵀ G_e E_e and
//! F_s − K_s C0 in the space's control-point numbering (rows of control points no element of
//! the share touches are empty), and the symmetric scaling D of the whole fit. Invariant:
//! summed over a partition of the elements, the shares give exactly the serial system
//! ([`super::normal_equations_with`]) up to the order of floating-point additions; D is
//! that of the serial fit.

use super::{ElementBlocks, FitParams, FitSpace, NormalMatrix, SmoothTargets};
use crate::mesh::{LinearMesh, Topology};

/// A [`FitSpace`] restricted to some of its elements (local index i is element `elements[i]`).
struct Subset<'a> {
    inner: &'a dyn FitSpace,
    elements: &'a [usize],
}

impl FitSpace for Subset<'_> {
    fn dim(&self) -> usize {
        self.inner.dim()
    }
    fn n_elements(&self) -> usize {
        self.elements.len()
    }
    fn control_points(&self) -> &[[f64; 3]] {
        self.inner.control_points()
    }
    fn element_rows(
        &self,
        e: usize,
        offsets: &mut Vec<usize>,
        cols: &mut Vec<u32>,
        weights: &mut Vec<f64>,
    ) {
        self.inner
            .element_rows(self.elements[e], offsets, cols, weights)
    }
    fn bezier_net_with(&self, e: usize, cps: &[[f64; 3]]) -> [[f64; 3]; 27] {
        self.inner.bezier_net_with(self.elements[e], cps)
    }
    fn element_pattern(&self, e: usize, ids: &mut Vec<u32>) -> Option<u64> {
        self.inner.element_pattern(self.elements[e], ids)
    }
    fn add_transposed(&self, e: usize, f: &[[f64; 3]; 27], out: &mut Vec<(u32, [f64; 3])>) {
        self.inner.add_transposed(self.elements[e], f, out)
    }
}

/// One share of the fit's system: K_s, the right-hand side F_s − K_s C0 (both unscaled), and
/// the scaling D of the whole fit (`None`: identity), as described in the module docs.
pub struct PartialSystem {
    pub matrix: NormalMatrix,
    pub rhs: Vec<[f64; 3]>,
    pub scale: Option<Vec<f64>>,
}

/// The share of the fit's normal equations over `elements` (indices of `mesh`).
pub fn partial_normal_equations(
    space: &dyn FitSpace,
    mesh: &LinearMesh,
    topo: &Topology,
    params: &FitParams,
    smooth: Option<&SmoothTargets>,
    elements: &[usize],
) -> PartialSystem {
    let blocks = ElementBlocks::with_features(
        space,
        mesh,
        topo,
        &params.weights,
        params.features.as_deref(),
    );
    let rhs = super::rhs::displacement_rhs_of(
        space,
        mesh,
        topo,
        &params.weights,
        &blocks.masks,
        smooth,
        Some(elements),
    );
    let sub_blocks = ElementBlocks {
        masks: elements.iter().map(|&e| blocks.masks[e]).collect(),
        cache: blocks.cache,
    };
    let subset = Subset {
        inner: space,
        elements,
    };
    let matrix = super::assembly::assemble_matrix(&subset, &sub_blocks);
    let scale = super::control_point_scales(space, &super::size_levels(mesh));
    PartialSystem { matrix, rhs, scale }
}
