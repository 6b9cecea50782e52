//! Reading a high-order mesh back from a file's [`RawMesh`].

use super::ordering::{gmsh_hex, gmsh_line, gmsh_quad, vtk_hex, vtk_quad};
use crate::mesh::HighOrderMesh;
use crate::mesh::high_order::lattice_index;
use crate::mesh::raw::{CellKind, Location, NodeConvention, ParseError, RawMesh};

/// Node order and dimension/order of a block's cells, if they are lines, quads or hexes.
fn shape(kind: &CellKind) -> Option<(usize, usize, NodeConvention)> {
    match kind {
        CellKind::Line => Some((1, 1, NodeConvention::Gmsh)),
        CellKind::Quad => Some((2, 1, NodeConvention::Gmsh)),
        CellKind::Hexahedron => Some((3, 1, NodeConvention::Gmsh)),
        CellKind::Lagrange {
            dim,
            order,
            convention,
        } => Some((*dim, *order, *convention)),
        _ => None,
    }
}

/// File node s of a cell → lattice index, for the convention.
fn permutation(dim: usize, p: usize, convention: NodeConvention) -> Vec<usize> {
    let order = match (dim, convention) {
        (1, _) => gmsh_line(p),
        (2, NodeConvention::Gmsh | NodeConvention::Abaqus) => gmsh_quad(p),
        (2, NodeConvention::Vtk) => vtk_quad(p),
        (2, NodeConvention::Cgns) => crate::io::cgns::ordering::cgns_quad(p),
        (3, NodeConvention::Gmsh) => gmsh_hex(p),
        (3, NodeConvention::Cgns) => crate::io::cgns::ordering::cgns_hex(p),
        // Abaqus defines one 27-node hexahedron (order 2).
        (3, NodeConvention::Abaqus) => crate::io::abaqus_write::c3d27(),
        _ => vtk_hex(p),
    };
    order.iter().map(|&l| lattice_index(p, l)).collect()
}

impl HighOrderMesh {
    /// Build a high-order mesh from a file's cells: the quads or hexes of one order (linear
    /// or Lagrange) are the elements, lines or quads of the same order with tags the
    /// boundary. Errors name the place and the problem.
    pub fn from_raw(raw: RawMesh) -> Result<HighOrderMesh, ParseError> {
        let dim = raw
            .blocks
            .iter()
            .filter_map(|b| shape(b.kind()).map(|s| s.0))
            .max()
            .filter(|&d| d >= 2)
            .ok_or_else(|| {
                ParseError::new(Location::File, "no quadrilateral or hexahedral elements")
            })?;
        let mut order = None;
        let mut mesh = HighOrderMesh {
            dim,
            ..Default::default()
        };
        let n_points = raw.points.len();
        for want_dim in [dim, dim - 1] {
            for b in &raw.blocks {
                let Some((d, p, conv)) = shape(b.kind()) else {
                    continue;
                };
                if d != want_dim || b.is_empty() {
                    continue;
                }
                if want_dim == dim {
                    if order.is_some_and(|o| o != p) {
                        return Err(ParseError::new(
                            b.location(0),
                            format!("elements of orders {} and {p} in one mesh", order.unwrap()),
                        ));
                    }
                    order = Some(p);
                } else if Some(p) != order {
                    continue;
                }
                let perm = permutation(d, p, conv);
                let (target, tags) = if d == dim {
                    (&mut mesh.elements, &mut mesh.element_tags)
                } else {
                    (&mut mesh.boundary, &mut mesh.boundary_tags)
                };
                let npc = b.nodes_per_cell;
                for c in 0..b.len() {
                    let cell = &b.nodes[c * npc..(c + 1) * npc];
                    let mut lattice = vec![0u32; npc];
                    for (s, &n) in cell.iter().enumerate() {
                        if n < 0 || n as usize >= n_points {
                            return Err(ParseError::new(
                                b.location(c),
                                format!(
                                    "cell refers to node {}, but the file defines {n_points} nodes",
                                    n + 1
                                ),
                            ));
                        }
                        lattice[perm[s]] = n as u32;
                    }
                    target.extend_from_slice(&lattice);
                    tags.push(b.tags.get(c).copied().unwrap_or(0));
                }
            }
        }
        mesh.order = order.unwrap_or(1);
        if let Some((i, k)) = raw
            .points
            .iter()
            .enumerate()
            .find_map(|(i, p)| p.iter().position(|c| !c.is_finite()).map(|k| (i, k)))
        {
            let loc = raw.point_locations.get(i).copied().unwrap_or_default();
            return Err(ParseError::new(
                loc,
                format!(
                    "node {} has a non-finite coordinate {}",
                    i + 1,
                    ["x", "y", "z"][k]
                ),
            ));
        }
        mesh.nodes = raw.points;
        mesh.tag_names = raw.tag_names;
        if mesh.element_tags.iter().all(|&t| t == 0) {
            mesh.element_tags.clear();
        }
        Ok(mesh)
    }
}
