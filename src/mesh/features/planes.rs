//! Planar patches (3D) and straight chains (2D): the least-squares plane or line of each
//! patch, kept only when every vertex of the patch lies within a tolerance of it.
//!
//! Input: the patch of each boundary facet. Output: per patch, `Some((unit normal, offset))`
//! of the plane or line n·x = offset, or `None`.

use crate::math::linalg::{DVec3, unit};
use crate::mesh::{LinearMesh, Topology};

/// 2D: the lines (unit normal with zero z, offset) of the boundary chains whose vertices all
/// lie within `tol` of their least-squares line; a chain of one edge is straight.
pub(super) fn straight_chains(
    mesh: &LinearMesh,
    topo: &Topology,
    facet_patch: &[u32],
    n_patches: usize,
    tol: f64,
) -> Vec<Option<([f64; 3], f64)>> {
    // Per chain: the vertex count and sums of x, y (each edge's two ends).
    let mut sums = vec![[0.0f64; 3]; n_patches];
    for (i, &f) in topo.boundary_facets.iter().enumerate() {
        for v in topo.edges[f as usize] {
            let x = mesh.coords[v as usize];
            let s = &mut sums[facet_patch[i] as usize];
            *s = [s[0] + 1.0, s[1] + x[0], s[2] + x[1]];
        }
    }
    let centre: Vec<[f64; 2]> = sums.iter().map(|s| [s[1] / s[0], s[2] / s[0]]).collect();
    let mut moments = vec![[0.0f64; 3]; n_patches];
    for (i, &f) in topo.boundary_facets.iter().enumerate() {
        let p = facet_patch[i] as usize;
        for v in topo.edges[f as usize] {
            let x = mesh.coords[v as usize];
            let (dx, dy) = (x[0] - centre[p][0], x[1] - centre[p][1]);
            let m = &mut moments[p];
            *m = [m[0] + dx * dx, m[1] + dx * dy, m[2] + dy * dy];
        }
    }
    let mut lines: Vec<Option<([f64; 3], f64)>> = (0..n_patches)
        .map(|p| {
            let [xx, xy, yy] = moments[p];
            // The principal direction of the chain's points; its normal.
            let phi = 0.5 * (2.0 * xy).atan2(xx - yy);
            let n = [-phi.sin(), phi.cos(), 0.0];
            (xx + yy > 0.0).then(|| (n, n[0] * centre[p][0] + n[1] * centre[p][1]))
        })
        .collect();
    drop_off_fits(mesh, topo, facet_patch, &mut lines, tol);
    lines
}

/// Planes of the patches whose vertices are all within `tol` of their area-weighted plane.
pub(super) fn planar_patches(
    mesh: &LinearMesh,
    topo: &Topology,
    facet_patch: &[u32],
    n_patches: usize,
    tol: f64,
) -> Vec<Option<([f64; 3], f64)>> {
    // Per patch: the summed area vector, and the sum and count of its facets' corners.
    let mut area = vec![DVec3::ZERO; n_patches];
    let mut centre = vec![(DVec3::ZERO, 0.0); n_patches];
    for (i, &f) in topo.boundary_facets.iter().enumerate() {
        let q = topo.faces[f as usize];
        let x = |k: usize| DVec3::from(mesh.coords[q[k] as usize]);
        let p = facet_patch[i] as usize;
        area[p] += (x(2) - x(0)).cross(x(3) - x(1));
        for k in 0..4 {
            centre[p].0 += x(k);
            centre[p].1 += 1.0;
        }
    }
    let mut planes: Vec<Option<([f64; 3], f64)>> = (0..n_patches)
        .map(|p| {
            (area[p].length() > 0.0).then(|| {
                let n = unit(area[p]);
                let c = centre[p].0 / centre[p].1;
                (n.into(), n.dot(c))
            })
        })
        .collect();
    drop_off_fits(mesh, topo, facet_patch, &mut planes, tol);
    planes
}

/// Drop the line or plane `fits[p]` (unit normal, offset) of every patch p that has a vertex
/// of one of its facets ([`Topology::facet_vertices`]: a 2D edge's two ends, a 3D face's four
/// corners) more than `tol` off it.
fn drop_off_fits(
    mesh: &LinearMesh,
    topo: &Topology,
    facet_patch: &[u32],
    fits: &mut [Option<([f64; 3], f64)>],
    tol: f64,
) {
    for (i, &f) in topo.boundary_facets.iter().enumerate() {
        let p = facet_patch[i] as usize;
        if let Some((n, d)) = fits[p]
            && topo
                .facet_vertices(f as usize)
                .iter()
                .any(|&v| (DVec3::from(n).dot(mesh.coords[v as usize].into()) - d).abs() > tol)
        {
            fits[p] = None;
        }
    }
}
