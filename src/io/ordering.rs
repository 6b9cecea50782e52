//! Node orderings of Lagrange quads and hexes of any order in Gmsh and VTK files.
//!
//! A high-order element's nodes sit on the equispaced lattice `(i, j[, k])`, `0 ≤ i, j, k ≤ p`.
//! polyspline keeps them in *lattice order* (i fastest, then j, then k); a writer emits them in
//! the order its format expects, `ordering[s]` being the lattice point of the format's node `s`.
//!
//! * **Gmsh** (MSH 2.2 and 4.1): corners, then edge interiors edge by edge (quad edges cyclic
//!   0→1→2→3→0; hex edges 0–1, 0–3, 0–4, 1–2, 1–5, 2–3, 2–6, 3–7, 4–5, 4–7, 5–6, 6–7), then
//!   face interiors as Gmsh quads of order p−2 laid on each face from its first vertex, then the
//!   interior as a Gmsh element of order p−2 (recursive).
//! * **VTK Lagrange** (types 68/70/72, file version ≥ 2.1 / legacy 5.1): corners, edges running
//!   toward increasing lattice index, faces i=0, i=p, j=0, j=p, k=0, k=p each lexicographic, then
//!   the interior lexicographic (not recursive).
//!
//! The tables in `tests/library/node_ordering.rs`, produced by Gmsh 4.15 and VTK 9.7 themselves, are the
//! tests' oracle.

use crate::mesh::high_order::{Lattice, lattice_index};

/// Gmsh node order of a quad of order `p` (p ≥ 1): lattice point of each Gmsh node.
pub fn gmsh_quad(p: usize) -> Vec<Lattice> {
    let mut out = Vec::with_capacity((p + 1) * (p + 1));
    gmsh_quad_into(p, &mut out);
    out
}

fn gmsh_quad_into(p: usize, out: &mut Vec<Lattice>) {
    if p == 0 {
        out.push([0, 0, 0]);
        return;
    }
    out.extend([[0, 0, 0], [p, 0, 0], [p, p, 0], [0, p, 0]]);
    if p == 1 {
        return;
    }
    out.extend((1..p).map(|i| [i, 0, 0]));
    out.extend((1..p).map(|j| [p, j, 0]));
    out.extend((1..p).rev().map(|i| [i, p, 0]));
    out.extend((1..p).rev().map(|j| [0, j, 0]));
    let start = out.len();
    gmsh_quad_into(p - 2, out);
    for l in &mut out[start..] {
        l[0] += 1;
        l[1] += 1;
    }
}

/// Gmsh hex edges as pairs of corner numbers.
pub const GMSH_HEX_EDGES: [[usize; 2]; 12] = [
    [0, 1],
    [0, 3],
    [0, 4],
    [1, 2],
    [1, 5],
    [2, 3],
    [2, 6],
    [3, 7],
    [4, 5],
    [4, 7],
    [5, 6],
    [6, 7],
];

/// Gmsh hex faces as corner cycles (outward normals).
pub const GMSH_HEX_FACES: [[usize; 4]; 6] = [
    [0, 3, 2, 1],
    [0, 1, 5, 4],
    [0, 4, 7, 3],
    [1, 2, 6, 5],
    [2, 3, 7, 6],
    [4, 5, 6, 7],
];

/// Corner lattice points of the unit hex (times p gives the order-p corners).
const CORNERS: [[usize; 3]; 8] = [
    [0, 0, 0],
    [1, 0, 0],
    [1, 1, 0],
    [0, 1, 0],
    [0, 0, 1],
    [1, 0, 1],
    [1, 1, 1],
    [0, 1, 1],
];

/// Gmsh node order of a hex of order `p` (p ≥ 1).
pub fn gmsh_hex(p: usize) -> Vec<Lattice> {
    let mut out = Vec::with_capacity((p + 1).pow(3));
    gmsh_hex_into(p, &mut out);
    out
}

fn gmsh_hex_into(p: usize, out: &mut Vec<Lattice>) {
    if p == 0 {
        out.push([0, 0, 0]);
        return;
    }
    let corner = |c: usize| CORNERS[c].map(|x| x * p);
    out.extend((0..8).map(corner));
    if p == 1 {
        return;
    }
    // Point at step t (out of p) from corner a toward corner b.
    let along = |a: usize, b: usize, t: usize| -> Lattice {
        let (pa, pb) = (corner(a), corner(b));
        std::array::from_fn(|k| (pa[k] * (p - t) + pb[k] * t) / p)
    };
    for [a, b] in GMSH_HEX_EDGES {
        out.extend((1..p).map(|t| along(a, b, t)));
    }
    let mut sub = Vec::new();
    gmsh_quad_into(p - 2, &mut sub);
    for f in GMSH_HEX_FACES {
        let o = corner(f[0]);
        let du = unit_step(corner(f[0]), corner(f[1]));
        let dv = unit_step(corner(f[0]), corner(f[3]));
        for s in &sub {
            let (a, b) = (s[0] as isize + 1, s[1] as isize + 1);
            out.push(std::array::from_fn(|k| {
                (o[k] as isize + a * du[k] + b * dv[k]) as usize
            }));
        }
    }
    let start = out.len();
    gmsh_hex_into(p - 2, out);
    for l in &mut out[start..] {
        for x in l.iter_mut() {
            *x += 1;
        }
    }
}

fn unit_step(a: Lattice, b: Lattice) -> [isize; 3] {
    std::array::from_fn(|k| (b[k] as isize - a[k] as isize).signum())
}

/// VTK Lagrange quadrilateral (type 70) node order of order `p`.
pub fn vtk_quad(p: usize) -> Vec<Lattice> {
    let mut out = vec![[0, 0, 0], [p, 0, 0], [p, p, 0], [0, p, 0]];
    out.extend((1..p).map(|i| [i, 0, 0]));
    out.extend((1..p).map(|j| [p, j, 0]));
    out.extend((1..p).map(|i| [i, p, 0]));
    out.extend((1..p).map(|j| [0, j, 0]));
    for j in 1..p {
        out.extend((1..p).map(|i| [i, j, 0]));
    }
    out
}

/// VTK Lagrange hexahedron (type 72) node order of order `p` (VTK ≥ 9 numbering).
pub fn vtk_hex(p: usize) -> Vec<Lattice> {
    let mut out: Vec<Lattice> = CORNERS.iter().map(|c| c.map(|x| x * p)).collect();
    for k in [0, p] {
        out.extend((1..p).map(|i| [i, 0, k]));
        out.extend((1..p).map(|j| [p, j, k]));
        out.extend((1..p).map(|i| [i, p, k]));
        out.extend((1..p).map(|j| [0, j, k]));
    }
    for (i, j) in [(0, 0), (p, 0), (p, p), (0, p)] {
        out.extend((1..p).map(|k| [i, j, k]));
    }
    for i in [0, p] {
        for k in 1..p {
            out.extend((1..p).map(|j| [i, j, k]));
        }
    }
    for j in [0, p] {
        for k in 1..p {
            out.extend((1..p).map(|i| [i, j, k]));
        }
    }
    for k in [0, p] {
        for j in 1..p {
            out.extend((1..p).map(|i| [i, j, k]));
        }
    }
    for k in 1..p {
        for j in 1..p {
            out.extend((1..p).map(|i| [i, j, k]));
        }
    }
    out
}

/// Gmsh node order of a line of order `p`: end points, then the interior.
pub fn gmsh_line(p: usize) -> Vec<Lattice> {
    let mut out = vec![[0, 0, 0], [p, 0, 0]];
    out.extend((1..p).map(|i| [i, 0, 0]));
    out
}

/// VTK Lagrange curve (type 68) node order: the same as Gmsh's.
pub fn vtk_line(p: usize) -> Vec<Lattice> {
    gmsh_line(p)
}

/// Gmsh element type number of a Lagrange element of dimension `dim` (1 line, 2 quad, 3 hex)
/// and order `p` (1 ≤ p ≤ 10 for lines and quads, ≤ 9 for hexes), or `None`.
pub fn gmsh_type(dim: usize, p: usize) -> Option<u32> {
    const LINE: [u32; 10] = [1, 8, 26, 27, 28, 62, 63, 64, 65, 66];
    const QUAD: [u32; 10] = [3, 10, 36, 37, 38, 47, 48, 49, 50, 51];
    const HEX: [u32; 9] = [5, 12, 92, 93, 94, 95, 96, 97, 98];
    let table: &[u32] = match dim {
        1 => &LINE,
        2 => &QUAD,
        3 => &HEX,
        _ => return None,
    };
    p.checked_sub(1).and_then(|i| table.get(i)).copied()
}

/// The inverse of [`gmsh_type`] for Lagrange lines, quads and hexes: (dimension, order).
pub fn gmsh_type_info(t: u32) -> Option<(usize, usize)> {
    (1..=3).find_map(|dim| {
        (1..=10)
            .find(|&p| gmsh_type(dim, p) == Some(t))
            .map(|p| (dim, p))
    })
}

/// Map `ordering` (format node → lattice point) to format node → lattice index.
pub fn to_indices(p: usize, ordering: &[Lattice]) -> Vec<usize> {
    ordering.iter().map(|&l| lattice_index(p, l)).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn is_permutation(p: usize, dim: usize, o: &[Lattice]) -> bool {
        let n = (p + 1).pow(dim as u32);
        let mut seen = vec![false; n];
        for &l in o {
            let i = lattice_index(p, l);
            if i >= n || seen[i] {
                return false;
            }
            seen[i] = true;
        }
        o.len() == n
    }

    #[test]
    fn orderings_are_permutations_of_the_lattice() {
        for p in 1..=10 {
            assert!(is_permutation(p, 2, &gmsh_quad(p)), "gmsh quad {p}");
            assert!(is_permutation(p, 2, &vtk_quad(p)), "vtk quad {p}");
            assert!(is_permutation(p, 3, &gmsh_hex(p)), "gmsh hex {p}");
            assert!(is_permutation(p, 3, &vtk_hex(p)), "vtk hex {p}");
        }
    }

    #[test]
    fn gmsh_type_numbers_round_trip() {
        assert_eq!(gmsh_type(2, 2), Some(10));
        assert_eq!(gmsh_type(3, 3), Some(92));
        assert_eq!(gmsh_type(3, 10), None);
        for dim in 1..=3 {
            for p in 1..=9 {
                assert_eq!(gmsh_type_info(gmsh_type(dim, p).unwrap()), Some((dim, p)));
            }
        }
    }
}
