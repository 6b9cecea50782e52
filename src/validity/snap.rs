//! Snapping the output's boundary vertex nodes back onto the input vertices (paper §3),
//! keeping only the moves that leave every element certified valid.
//!
//! Input: the linear mesh, its topology and the sampled [`HighOrderMesh`] (vertex node ids =
//! input vertex ids). Output: the same mesh with some boundary vertex nodes moved; every element
//! containing a moved node is certified valid by the Lagrange det J certificate
//! ([`lagrange_element_bounds`]), and edge and face nodes never move.

use super::lagrange_element_bounds;
use crate::mesh::HighOrderMesh;
use crate::mesh::{LinearMesh, Topology};

/// Rounds of undoing snaps around elements that lose their certificate.
const MAX_SNAP_ROUNDS: usize = 8;

/// Move the output's boundary vertex nodes (node ids = input vertex ids) onto the input
/// vertices (paper §3), keeping only the moves after which every element containing a moved
/// node is still certified valid (det J of its Lagrange map, in Bernstein form). Returns the
/// number of vertices that really moved (not those already on their input vertex); edge and
/// face nodes are never moved.
pub fn snap_boundary(
    mesh: &LinearMesh,
    topo: &Topology,
    ho: &mut HighOrderMesh,
    depth: usize,
) -> usize {
    use rayon::prelude::*;
    let nv = mesh.n_vertices();
    let original: Vec<[f64; 3]> = ho.nodes[..nv].to_vec();
    let mut snapped = topo.vertex_on_boundary.clone();
    for v in 0..nv {
        if snapped[v] {
            ho.nodes[v] = mesh.coords[v];
        }
    }
    let corner_ids = |ho: &HighOrderMesh, e: usize| -> Vec<u32> {
        ho.element(e)
            .iter()
            .copied()
            .filter(|&n| (n as usize) < nv)
            .collect()
    };
    let mut affected: Vec<usize> = (0..ho.n_elements())
        .filter(|&e| corner_ids(ho, e).iter().any(|&n| snapped[n as usize]))
        .collect();
    for round in 0..=MAX_SNAP_ROUNDS {
        let bad: Vec<usize> = affected
            .par_iter()
            .copied()
            .filter(|&e| !lagrange_element_bounds(ho, e, depth).certified_positive())
            .collect();
        if bad.is_empty() {
            break;
        }
        // Undo the snaps of the failing elements (all of them in the last round).
        for &e in &bad {
            for n in corner_ids(ho, e) {
                let n = n as usize;
                if snapped[n] {
                    snapped[n] = false;
                    ho.nodes[n] = original[n];
                }
            }
        }
        if round == MAX_SNAP_ROUNDS {
            for (n, s) in snapped.iter_mut().enumerate() {
                if *s {
                    *s = false;
                    ho.nodes[n] = original[n];
                }
            }
        }
        affected = bad;
    }
    (0..nv)
        .filter(|&n| snapped[n] && original[n] != mesh.coords[n])
        .count()
}
