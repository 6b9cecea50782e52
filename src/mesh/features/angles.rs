//! Features by angle: 2D corners and 3D creases where the boundary's turning is above the
//! feature angle and concentrated (see the parent module's docs on coarse smooth boundaries).
//!
//! Input: the mesh, its topology and the feature angle. Output: per vertex (2D) or topology
//! edge (3D), whether the turning there makes a feature.

use super::CONCENTRATION;
use crate::math::linalg::DVec3;
use crate::mesh::topology::NONE;
use crate::mesh::{LinearMesh, Topology};

/// Whether a turning of `theta` degrees (signed, positive where the boundary is convex) is a
/// crease at `angle_deg`, given the signed turnings `beside` of the neighbouring edges across
/// (3D) or vertices along the boundary (2D), `None` where unknown. A smooth boundary sampled
/// coarsely turns by a lot everywhere, but smoothly: the next edge or vertex turns the same
/// way by a comparable angle. A crease concentrates its turning on one line with flatter
/// facets beside it. So the turning must exceed `angle_deg` and [`CONCENTRATION`] × the
/// smaller part of it that a neighbour turning the same way explains.
fn concentrated(theta: f64, beside: [Option<f64>; 2], angle_deg: f64) -> bool {
    if theta.abs().is_nan() || theta.abs() <= angle_deg {
        return false;
    }
    let explained = beside
        .iter()
        .map(|b| b.map_or(0.0, |b| (b * theta.signum()).clamp(0.0, theta.abs())))
        .fold(f64::INFINITY, f64::min);
    theta.abs() > CONCENTRATION * explained
}

fn centroid(xs: &[[f64; 3]]) -> DVec3 {
    let s = xs.iter().fold(DVec3::ZERO, |a, &x| a + DVec3::from(x));
    s / xs.len() as f64
}

/// 2D corners by angle: per vertex, whether it lies on two boundary edges and the boundary
/// turns there by a [`concentrated`] angle above `angle_deg`.
pub(super) fn corners_2d(mesh: &LinearMesh, topo: &Topology, angle_deg: f64) -> Vec<bool> {
    let nv = mesh.n_vertices();
    let x = |v: u32| DVec3::from(mesh.coords[v as usize]);
    // Boundary edges oriented with their element on the left, so the sign of the turning
    // says convex (positive) or re-entrant whatever the elements' own orientation.
    let (mut prev, mut next, mut count) = (vec![NONE; nv], vec![NONE; nv], vec![0u32; nv]);
    for &f in &topo.boundary_facets {
        let [mut p, mut q] = topo.edges[f as usize];
        let e = topo.facet_elements[f as usize][0] as usize;
        let c = centroid(&mesh.element_coords(e)[..4]);
        let (dq, dc) = (x(q) - x(p), c - x(p));
        if dq[0] * dc[1] - dq[1] * dc[0] < 0.0 {
            std::mem::swap(&mut p, &mut q);
        }
        next[p as usize] = q;
        prev[q as usize] = p;
        count[p as usize] += 1;
        count[q as usize] += 1;
    }
    let turning: Vec<Option<f64>> = (0..nv)
        .map(|v| {
            if count[v] != 2 || prev[v] == NONE || next[v] == NONE {
                return None;
            }
            let d1 = x(v as u32) - x(prev[v]);
            let d2 = x(next[v]) - x(v as u32);
            Some((d1.x * d2.y - d1.y * d2.x).atan2(d1.dot(d2)).to_degrees())
        })
        .collect();
    (0..nv)
        .map(|v| {
            turning[v].is_some_and(|t| {
                let beside = [prev[v], next[v]].map(|w| turning[w as usize]);
                concentrated(t, beside, angle_deg)
            })
        })
        .collect()
}

/// 3D creases by angle: per edge, whether it lies on two boundary faces whose unit normals
/// `normal` turn by a [`concentrated`] angle above `angle_deg`, against the edges opposite
/// it in those two faces. `edge_facets` lists the boundary facets (indices into
/// `topo.boundary_facets`) of each edge.
pub(super) fn creases_3d(
    mesh: &LinearMesh,
    topo: &Topology,
    normal: &[DVec3],
    edge_facets: &[Vec<usize>],
    angle_deg: f64,
) -> Vec<bool> {
    let x = |v: u32| mesh.coords[v as usize];
    // Outward normals (away from the element's centroid) and face centres.
    let mut out = normal.to_vec();
    let mut centre = vec![DVec3::ZERO; normal.len()];
    for (i, &f) in topo.boundary_facets.iter().enumerate() {
        centre[i] = centroid(&topo.faces[f as usize].map(x));
        let inside = centroid(&mesh.element_coords(topo.facet_elements[f as usize][0] as usize));
        if out[i].dot(inside - centre[i]) > 0.0 {
            out[i] = -out[i];
        }
    }
    let turning: Vec<Option<f64>> = edge_facets
        .iter()
        .map(|fs| match fs[..] {
            [i, j] => {
                let t = out[i].dot(out[j]).clamp(-1.0, 1.0).acos().to_degrees();
                // Convex where face j bends below face i's plane.
                Some(if out[i].dot(centre[j] - centre[i]) > 0.0 {
                    -t
                } else {
                    t
                })
            }
            _ => None,
        })
        .collect();
    let opposite = |i: usize, ed: usize| -> Option<usize> {
        let [a, b] = topo.edges[ed];
        let q = topo.faces[topo.boundary_facets[i] as usize];
        let rest: Vec<u32> = q.into_iter().filter(|&v| v != a && v != b).collect();
        let &[c, d] = &rest[..] else { return None };
        topo.edges.binary_search(&[c.min(d), c.max(d)]).ok()
    };
    edge_facets
        .iter()
        .enumerate()
        .map(|(ed, fs)| match (&fs[..], turning[ed]) {
            (&[i, j], Some(t)) => {
                let beside = [i, j].map(|k| opposite(k, ed).and_then(|o| turning[o]));
                concentrated(t, beside, angle_deg)
            }
            _ => false,
        })
        .collect()
}
