//! Who certifies a batch of elements ([`Certifier`]: the CPU reference [`CpuCertifier`] or the
//! GPU's), the certificate of a whole mesh ([`certify_mesh`]), and the demotion of elements
//! whose initial spline map is not certified ([`demote_with_rings`]).
//!
//! Invariant: every bound returned is a certified lower bound of det J on its element; where it
//! matters for a decision (at most the element's target) it is the exact certificate's.

use super::{DetBounds, certify_screened, det_jacobian_bounds};
use crate::math::BezierNet;
use crate::mesh::{LinearMesh, Topology};

/// Certified det J bounds of every element of a Bézier source.
pub fn certify_elements(
    dim: usize,
    n_elements: usize,
    net: impl Fn(usize) -> BezierNet + Sync,
    max_depth: usize,
) -> Vec<DetBounds> {
    use rayon::prelude::*;
    (0..n_elements)
        .into_par_iter()
        .map(|e| det_jacobian_bounds(dim, &net(e), max_depth))
        .collect()
}

/// Who computes certified det J bounds for a batch of elements: the CPU ([`CpuCertifier`]) or
/// the GPU (the execution floor's `GpuCertifier`). Both return bounds that are certified.
pub trait Certifier: Sync {
    /// Bounds of `elements`, in that order; `net(e)` is the Bézier net of element e.
    fn certify(
        &self,
        dim: usize,
        elements: &[usize],
        net: &(dyn Fn(usize) -> BezierNet + Sync),
        max_depth: usize,
    ) -> Vec<DetBounds>;
}

/// [`det_jacobian_bounds`] on every element, in parallel on the CPU (the reference).
pub struct CpuCertifier;

impl Certifier for CpuCertifier {
    fn certify(
        &self,
        dim: usize,
        elements: &[usize],
        net: &(dyn Fn(usize) -> BezierNet + Sync),
        max_depth: usize,
    ) -> Vec<DetBounds> {
        use rayon::prelude::*;
        elements
            .par_iter()
            .map(|&e| det_jacobian_bounds(dim, &net(e), max_depth))
            .collect()
    }
}

/// Certified det J bounds of the `n_elements` elements `net(e)`, screened
/// ([`crate::validity::screen`]): decisions "lower > t" for t ≤ `target(e)` and the smallest
/// bound are the exact certificate's; bounds above the target may be the screen's.
pub fn certify_mesh(
    certifier: &dyn Certifier,
    dim: usize,
    n_elements: usize,
    net: &(dyn Fn(usize) -> BezierNet + Sync),
    depth: usize,
    target: &(dyn Fn(usize) -> f64 + Sync),
) -> Vec<DetBounds> {
    let all: Vec<usize> = (0..n_elements).collect();
    let mut c = certify_screened(certifier, dim, &all, net, depth, target);
    c.refine_smallest(certifier, dim, &all, net, depth, 1);
    c.bounds
}

/// The elements whose bound is not certified positive.
pub fn uncertified(bounds: &[DetBounds]) -> Vec<usize> {
    (0..bounds.len())
        .filter(|&e| !bounds[e].certified_positive())
        .collect()
}

/// Rounds of demotion before giving up on an initially invalid spline map.
pub const MAX_DEMOTION_ROUNDS: usize = 16;

/// Mark `bad` elements for demotion; after the first round, or at once where a bad element is
/// Q2 already (demoting it again changes nothing), also every element sharing a vertex with
/// it, so repeated rounds grow a Q2 region around an area the spline cannot follow. (Growing by
/// facet neighbours only never frees a Q2 element constrained by spline neighbours across its
/// edges.)
pub fn demote_with_rings(
    mesh: &LinearMesh,
    topo: &Topology,
    bad: &[usize],
    round: usize,
    is_q2: &dyn Fn(usize) -> bool,
    demote: &mut [bool],
) {
    for &e in bad {
        demote[e] = true;
        if round > 0 || is_q2(e) {
            for &v in mesh.element(e) {
                for &n in topo.elements_at_vertex(v as usize) {
                    demote[n as usize] = true;
                }
            }
        }
    }
}
