//! Abaqus `.inp` output of an order-2 [`HighOrderMesh`], as Trixi.jl's `P4estMesh` reads a
//! standard Abaqus file (Trixi.jl 0.9.14 and later: `p4est_mesh_from_standard_abaqus`).
//!
//! Input: a mesh of order 2. Output: `*NODE` (id, x, y, z; z = 0 in 2D), the line
//! `******* E L E M E N T S *************` that Trixi.jl looks for, then per volume group
//! `*ELEMENT, type=M3D9` (2D, 9-node quadrilaterals) or `type=C3D27` (3D), one element a line
//! (`id, n1, ..., nN`, comma and blank separated, as Trixi.jl splits them), then per boundary
//! group `*NSET,NSET=name` with the ids of every node of its facets, sixteen a line, each line
//! ending in a comma (Trixi.jl drops the last field of each line). Trixi.jl assigns an element
//! face to the boundary whose node set holds its corners: pass the names as
//! `boundary_symbols`.
//!
//! Node orders (Abaqus's): M3D9 corners, the mid-side nodes of edges 1–2, 2–3, 3–4, 4–1, then
//! the centre; C3D27 corners, the mid-edge nodes of the bottom edges 1–2, 2–3, 3–4, 4–1, the
//! top edges 5–6, 6–7, 7–8, 8–5 and the vertical edges 1–5, 2–6, 3–7, 4–8, then the centre
//! (node 21) and the face centres bottom, top, y−, x+, y+, x− (22–27).
//!
//! Trixi.jl builds each element's map by transfinite interpolation from its edges (2D) or
//! faces (3D): it reads every node here but the interior ones.

use crate::io::gmsh_write::groups;
use crate::io::ordering::{gmsh_quad, vtk_hex};
use crate::mesh::HighOrderMesh;
use crate::mesh::high_order::{Lattice, lattice_index};
use std::io::{self, Write};

/// Abaqus C3D27 node order as lattice points: corners and mid-edge nodes as VTK's 27-node
/// hexahedron, then the centre and the face centres z−, z+, y−, x+, y+, x−.
pub fn c3d27() -> Vec<Lattice> {
    let mut out = vtk_hex(2);
    out.truncate(20);
    out.extend([
        [1, 1, 1],
        [1, 1, 0],
        [1, 1, 2],
        [1, 0, 1],
        [2, 1, 1],
        [1, 2, 1],
        [0, 1, 1],
    ]);
    out
}

/// Why a mesh cannot be written for Trixi.jl, as one line.
pub fn unsupported(mesh: &HighOrderMesh) -> Option<String> {
    (mesh.order != 2).then(|| {
        format!(
            "the Abaqus output is for Trixi.jl, which reads quadratic elements only (M3D9, C3D27); use --order 2, not {} (or write .msh, .vtu or .cgns)",
            mesh.order
        )
    })
}

/// A name Trixi.jl can read as a boundary symbol: letters, digits and `_`.
fn symbol(name: &str) -> String {
    let s: String = name
        .chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || c == '_' {
                c
            } else {
                '_'
            }
        })
        .collect();
    if s.is_empty() || s.starts_with(|c: char| c.is_ascii_digit()) {
        format!("_{s}")
    } else {
        s
    }
}

/// Write `mesh` (order 2) as Abaqus for Trixi.jl (module docs).
pub fn write_abaqus(mesh: &HighOrderMesh, volume_name: &str, w: &mut impl Write) -> io::Result<()> {
    if let Some(why) = unsupported(mesh) {
        return Err(io::Error::new(io::ErrorKind::InvalidInput, why));
    }
    let d = mesh.dim;
    writeln!(w, "*HEADING")?;
    writeln!(w, "Curved quadratic {}D mesh written by polyspline", d)?;
    writeln!(w, "*NODE")?;
    let mut f = zmij::Buffer::new();
    for (i, x) in mesh.nodes.iter().enumerate() {
        write!(w, "{}", i + 1)?;
        for c in x {
            write!(w, ", {}", f.format(*c))?;
        }
        writeln!(w)?;
    }
    writeln!(w, "******* E L E M E N T S *************")?;
    let (ty, order): (&str, Vec<Lattice>) = if d == 3 {
        ("C3D27", c3d27())
    } else {
        ("M3D9", gmsh_quad(2))
    };
    let perm: Vec<usize> = order.iter().map(|&l| lattice_index(2, l)).collect();
    let plan = groups(mesh, volume_name);
    let mut id = 0usize;
    for g in plan.iter().filter(|g| g.dim == d && !g.members.is_empty()) {
        writeln!(w, "*ELEMENT, type={ty}, ELSET={}", symbol(&g.name))?;
        for &e in &g.members {
            id += 1;
            let cell = mesh.element(e);
            write!(w, "{id}")?;
            for &s in &perm {
                write!(w, ", {}", cell[s] + 1)?;
            }
            writeln!(w)?;
        }
    }
    let npf = mesh.nodes_per_facet();
    for g in plan
        .iter()
        .filter(|g| g.dim + 1 == d && !g.members.is_empty())
    {
        let mut nodes: Vec<u32> = g
            .members
            .iter()
            .flat_map(|&m| mesh.boundary[m * npf..(m + 1) * npf].iter().copied())
            .collect();
        nodes.sort_unstable();
        nodes.dedup();
        writeln!(w, "*NSET,NSET={}", symbol(&g.name))?;
        for line in nodes.chunks(16) {
            for n in line {
                write!(w, "{},", n + 1)?;
            }
            writeln!(w)?;
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// C3D27 is a permutation of the order-2 lattice whose face centres sit on the faces
    /// Abaqus numbers them for.
    #[test]
    fn c3d27_is_a_permutation_with_abaqus_faces() {
        let c = c3d27();
        let mut seen = [false; 27];
        for &l in &c {
            let i = lattice_index(2, l);
            assert!(!seen[i]);
            seen[i] = true;
        }
        assert_eq!(c[20], [1, 1, 1]);
        // Faces 1–6: z−, z+, y−, x+, y+, x−.
        let faces = [(2, 0), (2, 2), (1, 0), (0, 2), (1, 2), (0, 0)];
        for (k, (axis, value)) in faces.iter().enumerate() {
            assert_eq!(c[21 + k][*axis], *value, "face {}", k + 1);
        }
    }

    #[test]
    fn symbols_are_julia_identifiers() {
        assert_eq!(symbol("inlet wall"), "inlet_wall");
        assert_eq!(symbol("1a"), "_1a");
    }
}
