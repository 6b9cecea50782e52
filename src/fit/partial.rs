//! The fit's normal equations summed over a subset of the elements: one rank's share of
//! K C = F in the distributed fit (the job floor's `distributed` runs it on every rank).
//!
//! Input: the spline space, the mesh and its topology, the fit's parameters and smooth
//! targets, and the elements of the share. Output: K_s = Σ_{e ∈ share} E_eᵀ G_e E_e and
//! F_s − K_s C0 in the space's control-point numbering (rows of control points no element of
//! the share touches are empty), and the symmetric scaling D of the whole fit. Invariant:
//! summed over a partition of the elements, the shares give exactly the serial system
//! ([`super::normal_equations_with`]) up to the order of floating-point additions; D is
//! that of the serial fit.

use super::{ElementBlocks, FitParams, FitSpace, NormalMatrix, SmoothTargets};
use crate::math::BezierNet;
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
    fn bezier_net_with(&self, e: usize, cps: &[[f64; 3]]) -> BezierNet {
        self.inner.bezier_net_with(self.elements[e], cps)
    }
    fn element_pattern(&self, e: usize, ids: &mut Vec<u32>) -> Option<u64> {
        self.inner.element_pattern(self.elements[e], ids)
    }
    fn element_factors(&self, e: usize, ids: &mut Vec<u32>) -> Option<[[[f64; 3]; 3]; 3]> {
        self.inner.element_factors(self.elements[e], ids)
    }
    fn add_transposed(&self, e: usize, f: &BezierNet, out: &mut Vec<(u32, [f64; 3])>) {
        self.inner.add_transposed(self.elements[e], f, out)
    }
    fn frames(&self, e: usize) -> Option<&[crate::spline::extraction::SeamFrame]> {
        self.inner.frames(self.elements[e])
    }
    fn has_frames(&self) -> bool {
        self.elements
            .iter()
            .any(|&e| self.inner.frames(e).is_some())
    }
}

/// One share of the fit's system: K_s, the right-hand side F_s − K_s C0 (both unscaled), and
/// the scaling D of the whole fit (`None`: identity), as described in the module docs.
pub struct PartialSystem {
    pub matrix: NormalMatrix,
    pub rhs: Vec<[f64; 3]>,
    pub scale: Option<Vec<f64>>,
    /// The share's C_s of the coupling across rotation seams ([`super::rotated`], unscaled):
    /// `None` when none of its elements sees a control point rotated. Summed over a partition
    /// of the elements, the shares give the serial C.
    pub coupling: Option<super::rotated::Coupling>,
}

/// Shortest edge of each element (the size h_e of [`super::size_levels`]).
pub fn element_sizes(mesh: &LinearMesh) -> Vec<f64> {
    (0..mesh.n_elements())
        .map(|e| super::normal_matrix::shortest_edge(mesh, e))
        .collect()
}

/// [`super::size_levels`] with the largest size `hmax` given: a mesh that is part of a
/// larger one takes the whole mesh's `hmax` so that its levels are the whole mesh's.
pub fn size_levels_below(sizes: &[f64], hmax: f64) -> Vec<u16> {
    sizes
        .iter()
        .map(|&he| {
            if he > 0.0 && hmax > 0.0 {
                ((hmax / he).log2().floor() - super::normal_matrix::LEVEL_DEAD_ZONE)
                    .clamp(0.0, super::normal_matrix::MAX_LEVEL as f64) as u16
            } else {
                0
            }
        })
        .collect()
}

/// An element block's matrix and right-hand-side coefficients.
type BlockPair = (Vec<f64>, Vec<f64>);

/// `blocks` with the size levels `levels` in place of its own (the blocks of a level are
/// 4^k times those of level 0, so they are rescaled exactly, by powers of 2).
fn relevel(blocks: ElementBlocks, levels: &[u16]) -> ElementBlocks {
    let low = !(super::normal_matrix::LEVEL_BITS << super::normal_matrix::LEVEL_SHIFT);
    let masks: Vec<u64> = blocks
        .masks
        .iter()
        .zip(levels)
        .map(|(&m, &k)| (m & low) | ((k as u64) << super::normal_matrix::LEVEL_SHIFT))
        .collect();
    // Each mask's level and element matrices at the level it was assembled.
    let mut base: std::collections::HashMap<u64, (i32, &BlockPair)> = Default::default();
    for (m, g) in &blocks.cache {
        base.entry(m & low)
            .or_insert((super::normal_matrix::mask_level(*m) as i32, g));
    }
    let mut cache = std::collections::HashMap::new();
    for &m in &masks {
        cache.entry(m).or_insert_with(|| {
            let (k0, (gd, gr)) = base[&(m & low)];
            let f = 4.0f64.powi(super::normal_matrix::mask_level(m) as i32 - k0);
            (
                gd.iter().map(|x| f * x).collect(),
                gr.iter().map(|x| f * x).collect(),
            )
        });
    }
    ElementBlocks { masks, cache }
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
    partial_normal_equations_levelled(space, mesh, topo, params, smooth, elements, None)
}

/// [`partial_normal_equations`] with the size levels of the elements given (`None`: those of
/// `mesh` itself, [`super::size_levels`]): a rank's sub-mesh passes the levels under the
/// whole mesh's largest size ([`size_levels_below`]).
pub fn partial_normal_equations_levelled(
    space: &dyn FitSpace,
    mesh: &LinearMesh,
    topo: &Topology,
    params: &FitParams,
    smooth: Option<&SmoothTargets>,
    elements: &[usize],
    levels: Option<&[u16]>,
) -> PartialSystem {
    let mut blocks = ElementBlocks::with_features(
        space,
        mesh,
        topo,
        &params.weights,
        params.features.as_deref(),
    );
    let own_levels;
    let levels = match levels {
        Some(l) => {
            blocks = relevel(blocks, l);
            l
        }
        None => {
            own_levels = super::size_levels(mesh);
            &own_levels
        }
    };
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
    let coupling = super::rotated::Coupling::of(&subset, &sub_blocks);
    let scale = super::control_point_scales(space, levels);
    PartialSystem {
        matrix,
        rhs,
        scale,
        coupling,
    }
}
