//! CGNS node orders of the Lagrange bars, quadrilaterals and hexahedra it defines (orders 1–4:
//! `BAR_2..5`, `QUAD_4/9/16/25`, `HEXA_8/27/64/125`), as lattice points in polyspline's
//! convention ([`crate::mesh::high_order::Lattice`]: `ordering[s]` is the lattice point of file
//! node `s`).
//!
//! The SIDS rules: corners; edge interiors (quad edges cyclic 0→1→2→3→0; hex: the bottom edges
//! cyclic, then the four mounting edges 0→4, 1→5, 2→6, 3→7, then the top edges cyclic); face
//! interiors of a hexahedron in the order bottom (0,1,2,3), sides (0,1,5,4), (1,2,6,5),
//! (2,3,7,6), (3,0,4,7), top (4,5,6,7); then the volume interior plane by plane from the bottom.
//! The interior of a face (and of each interior plane) is the ring of nodes one step inside its
//! boundary, cyclic from the node next to its first corner toward its second, then the centre
//! node (orders 2 and 4). Unlike Gmsh's, these interiors are not recursive: `QUAD_25` and
//! `HEXA_125` differ from Gmsh's types 37 and 93, and every hexahedron from Gmsh's edge order.

use crate::mesh::high_order::Lattice;

/// Highest order CGNS defines for quadrilaterals and hexahedra.
pub const MAX_ORDER: usize = 4;

/// The interior nodes of an order-`p` quadrilateral whose corners sit at the lattice points
/// `c` (a face or a plane of a hexahedron, or the quadrilateral itself).
fn quad_interior(p: usize, c: [Lattice; 4], out: &mut Vec<Lattice>) {
    // Local (a, b) in 0..=p along c0→c1 and c0→c3, mapped affinely onto the lattice.
    let map = |a: usize, b: usize| -> Lattice {
        std::array::from_fn(|k| {
            let o = c[0][k] as i64;
            let du = c[1][k] as i64 - o;
            let dv = c[3][k] as i64 - o;
            (o + (du * a as i64 + dv * b as i64) / p as i64) as usize
        })
    };
    if p > 2 {
        let (lo, hi) = (1, p - 1);
        let ring = [(lo, lo), (hi, lo), (hi, hi), (lo, hi)];
        for s in 0..4 {
            let (a0, b0) = ring[s];
            let (a1, b1) = ring[(s + 1) % 4];
            for t in 0..p - 2 {
                let step = |x0: usize, x1: usize| {
                    if x1 >= x0 { x0 + t } else { x0 - t }
                };
                let (a, b) = (
                    if a0 == a1 { a0 } else { step(a0, a1) },
                    if b0 == b1 { b0 } else { step(b0, b1) },
                );
                out.push(map(a, b));
            }
        }
    }
    if p == 2 || p == 4 {
        out.push(map(p / 2, p / 2));
    }
}

/// The nodes strictly inside the segment from `a` to `b`, from `a`.
fn edge(p: usize, a: Lattice, b: Lattice, out: &mut Vec<Lattice>) {
    for t in 1..p {
        out.push(std::array::from_fn(|k| {
            (a[k] as i64 + (b[k] as i64 - a[k] as i64) * t as i64 / p as i64) as usize
        }));
    }
}

/// CGNS node order of a quadrilateral of order `p` (1..=4).
pub fn cgns_quad(p: usize) -> Vec<Lattice> {
    let c = [[0, 0, 0], [p, 0, 0], [p, p, 0], [0, p, 0]];
    let mut out = c.to_vec();
    for s in 0..4 {
        edge(p, c[s], c[(s + 1) % 4], &mut out);
    }
    quad_interior(p, c, &mut out);
    out
}

/// CGNS node order of a hexahedron of order `p` (1..=4).
pub fn cgns_hex(p: usize) -> Vec<Lattice> {
    let c: [Lattice; 8] = [
        [0, 0, 0],
        [p, 0, 0],
        [p, p, 0],
        [0, p, 0],
        [0, 0, p],
        [p, 0, p],
        [p, p, p],
        [0, p, p],
    ];
    let mut out = c.to_vec();
    for s in 0..4 {
        edge(p, c[s], c[(s + 1) % 4], &mut out);
    }
    for s in 0..4 {
        edge(p, c[s], c[s + 4], &mut out);
    }
    for s in 0..4 {
        edge(p, c[s + 4], c[(s + 1) % 4 + 4], &mut out);
    }
    quad_interior(p, [c[0], c[1], c[2], c[3]], &mut out);
    for s in 0..4 {
        let n = (s + 1) % 4;
        quad_interior(p, [c[s], c[n], c[n + 4], c[s + 4]], &mut out);
    }
    quad_interior(p, [c[4], c[5], c[6], c[7]], &mut out);
    for k in 1..p {
        quad_interior(p, [[0, 0, k], [p, 0, k], [p, p, k], [0, p, k]], &mut out);
    }
    out
}

/// The CGNS element type code and name of a Lagrange cell of dimension `dim` (1–3) and order
/// `p`, if CGNS defines one.
pub fn cgns_type(dim: usize, p: usize) -> Option<(i32, &'static str)> {
    Some(match (dim, p) {
        (1, 1) => (3, "BAR_2"),
        (1, 2) => (4, "BAR_3"),
        (1, 3) => (24, "BAR_4"),
        (1, 4) => (40, "BAR_5"),
        (2, 1) => (7, "QUAD_4"),
        (2, 2) => (9, "QUAD_9"),
        (2, 3) => (28, "QUAD_16"),
        (2, 4) => (44, "QUAD_25"),
        (3, 1) => (17, "HEXA_8"),
        (3, 2) => (19, "HEXA_27"),
        (3, 3) => (39, "HEXA_64"),
        (3, 4) => (56, "HEXA_125"),
        _ => return None,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::high_order::lattice_index;

    /// Every lattice point exactly once, for every order.
    #[test]
    fn orders_are_permutations_of_the_lattice() {
        for p in 1..=MAX_ORDER {
            for (dim, ord) in [(2, cgns_quad(p)), (3, cgns_hex(p))] {
                let n = (p + 1).pow(dim);
                assert_eq!(ord.len(), n, "dim {dim} order {p}");
                let mut seen = vec![false; n];
                for l in &ord {
                    let i = lattice_index(p, *l);
                    assert!(!seen[i], "dim {dim} order {p}: {l:?} twice");
                    seen[i] = true;
                }
            }
        }
    }

    /// The SIDS figures: `QUAD_25` interior ring and `HEXA_27` edges and faces.
    #[test]
    fn sids_figures() {
        let q = cgns_quad(4);
        assert_eq!(
            &q[16..],
            &[
                [1, 1, 0],
                [2, 1, 0],
                [3, 1, 0],
                [3, 2, 0],
                [3, 3, 0],
                [2, 3, 0],
                [1, 3, 0],
                [1, 2, 0],
                [2, 2, 0]
            ]
        );
        let h = cgns_hex(2);
        assert_eq!(&h[8..12], &[[1, 0, 0], [2, 1, 0], [1, 2, 0], [0, 1, 0]]);
        assert_eq!(&h[12..16], &[[0, 0, 1], [2, 0, 1], [2, 2, 1], [0, 2, 1]]);
        assert_eq!(
            &h[20..],
            &[
                [1, 1, 0],
                [1, 0, 1],
                [2, 1, 1],
                [1, 2, 1],
                [0, 1, 1],
                [1, 1, 2],
                [1, 1, 1]
            ]
        );
    }
}
