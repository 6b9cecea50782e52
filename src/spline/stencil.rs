//! Topological 3^d stencils of spline elements (`polyspline.md` §2.2).
//!
//! Input: a [`LinearMesh`] and its [`Topology`]. Output: for a spline-compatible element, the
//! [`Entity`] in each stencil slot a ∈ {0,1,2}^d (local index 9z + 3y + x), or the
//! [`Q2Reason`] that demotes it.
//!
//! A slot with offsets o = a − 1 is resolved by crossing, in every ordering of its non-zero
//! directions, the side of the current element in that direction. When crossing from X into
//! N through facet F, each remaining direction is *transported*: its side τ of X meets F in a
//! sub-entity s (an edge in 3D, a vertex in 2D) and its new side is the other facet of N that
//! contains s. The orderings with the most successful crossings decide: no remaining
//! direction gives `Cell(N)`; otherwise the intersection of N's remaining sides (which must
//! all be boundary) gives a `BFace`, `BEdge` or `BVertex`. Tied orderings must agree, or the
//! element is demoted. Frames of neighbours are never consulted, so elements whose local
//! frames are rotated or mirrored relative to each other share control points by entity.
//!
//! The transport of every (element, side, side) triple is tabulated once
//! (`transport_table`), so a crossing is a table look-up and the whole construction is
//! linear in the number of elements.

use super::classify::{Q2Reason, corner_of};
use crate::math::bernstein::net_len;
use crate::math::reference::{HEX_EDGES, HEX_SIDES, QUAD_SIDES};
use crate::mesh::LinearMesh;
use crate::mesh::topology::{NONE, Topology};
use rayon::prelude::*;

/// A spline control point's mesh entity (`polyspline.md` §2.1).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, serde::Serialize)]
pub enum Entity {
    /// The cell node of element e (vertex average of e).
    Cell(u32),
    /// 3D: a boundary face (vertex average of the face).
    BFace(u32),
    /// A boundary edge (midpoint).
    BEdge(u32),
    /// A boundary vertex (the vertex).
    BVertex(u32),
}

const KIND_SHIFT: u32 = 30;
const ID_MASK: u32 = (1 << KIND_SHIFT) - 1;

impl Entity {
    /// Pack into a u32: kind in the top two bits. Ids must be below 2^30.
    #[inline]
    pub(crate) fn pack(self) -> u32 {
        let (k, id) = match self {
            Entity::Cell(i) => (0, i),
            Entity::BFace(i) => (1, i),
            Entity::BEdge(i) => (2, i),
            Entity::BVertex(i) => (3, i),
        };
        debug_assert!(id <= ID_MASK);
        (k << KIND_SHIFT) | id
    }

    #[inline]
    pub(crate) fn unpack(p: u32) -> Entity {
        let id = p & ID_MASK;
        match p >> KIND_SHIFT {
            0 => Entity::Cell(id),
            1 => Entity::BFace(id),
            2 => Entity::BEdge(id),
            _ => Entity::BVertex(id),
        }
    }
}

/// Largest entity count the packed stencil representation supports.
pub(crate) const MAX_ENTITIES: usize = ID_MASK as usize;

/// Corner bit masks of the local sides (quads use the first four entries).
pub(crate) const fn side_masks(dim: usize) -> [u8; 6] {
    let mut m = [0u8; 6];
    let mut s = 0;
    while s < 2 * dim {
        let mut c = 0;
        if dim == 2 {
            while c < 2 {
                m[s] |= 1 << QUAD_SIDES[s][c];
                c += 1;
            }
        } else {
            while c < 4 {
                m[s] |= 1 << HEX_SIDES[s][c];
                c += 1;
            }
        }
        s += 1;
    }
    m
}

const QUAD_MASKS: [u8; 6] = side_masks(2);
const HEX_MASKS: [u8; 6] = side_masks(3);

#[inline]
pub(crate) fn masks(dim: usize) -> &'static [u8; 6] {
    if dim == 2 { &QUAD_MASKS } else { &HEX_MASKS }
}

/// Local hex edge (index into [`HEX_EDGES`]) with the given two-corner mask.
pub(crate) fn hex_edge_with_mask(mask: u8) -> Option<usize> {
    HEX_EDGES
        .iter()
        .position(|&[a, b]| (1u8 << a) | (1u8 << b) == mask)
}

/// Crossing data of one element, one cache line: the neighbour across each side (`NONE` for
/// none) and `tr[σ][τ]`, the side of that neighbour continuing side τ (`u8::MAX` where
/// undefined: no neighbour, τ parallel to σ, or no match).
#[derive(Clone, Copy, Debug)]
#[repr(C, align(64))]
pub(crate) struct Cross {
    pub nb: [u32; 6],
    pub tr: [[u8; 6]; 6],
}

/// For each corner mask, the sides containing all its corners (up to two, `u8::MAX` padding).
const fn sides_containing(dim: usize) -> [[u8; 2]; 256] {
    let m = side_masks(dim);
    let mut t = [[u8::MAX; 2]; 256];
    let mut mask = 1;
    while mask < 256 {
        let mut n = 0;
        let mut s = 0;
        while s < 2 * dim {
            if m[s] & mask as u8 == mask as u8 && n < 2 {
                t[mask][n] = s as u8;
                n += 1;
            }
            s += 1;
        }
        mask += 1;
    }
    t
}

const QUAD_SIDES_OF: [[u8; 2]; 256] = sides_containing(2);
const HEX_SIDES_OF: [[u8; 2]; 256] = sides_containing(3);

/// The crossing table of every element (see [`Cross`]).
pub(crate) fn transport_table(mesh: &LinearMesh, topo: &Topology) -> Vec<Cross> {
    let dim = topo.dim;
    let ns = topo.sides();
    let m = masks(dim);
    let sides_of = if dim == 2 {
        &QUAD_SIDES_OF
    } else {
        &HEX_SIDES_OF
    };
    (0..topo.n_elements)
        .into_par_iter()
        .map(|x| {
            let mut t = Cross {
                nb: [NONE; 6],
                tr: [[u8::MAX; 6]; 6],
            };
            let xv = mesh.element(x);
            for sigma in 0..ns {
                let n = topo.neighbor(x, sigma);
                t.nb[sigma] = n;
                if n == NONE {
                    continue;
                }
                let f = topo.element_facet(x, sigma) as usize;
                let sigma_n = if topo.facet_elements[f][0] == x as u32 {
                    topo.facet_sides[f][1]
                } else {
                    topo.facet_sides[f][0]
                };
                // Corners of the shared facet: x's local corner → n's local corner bit.
                let nv = mesh.element(n as usize);
                let mut cmap = [0u8; 8];
                let mut ok = true;
                for (c, bit) in cmap.iter_mut().enumerate() {
                    if m[sigma] & (1 << c) != 0 {
                        match corner_of(nv, xv[c]) {
                            Some(cn) => *bit = 1 << cn,
                            None => ok = false,
                        }
                    }
                }
                if !ok {
                    continue;
                }
                for tau in 0..ns {
                    if tau / 2 == sigma / 2 {
                        continue;
                    }
                    let sub = m[tau] & m[sigma];
                    let sub_n = (0..8)
                        .filter(|&c| sub & (1 << c) != 0)
                        .fold(0u8, |a, c| a | cmap[c]);
                    let [s0, s1] = sides_of[sub_n as usize];
                    // The sub-entity must lie on n's shared side; take n's other side.
                    if s0 == sigma_n && s1 != u8::MAX {
                        t.tr[sigma][tau] = s1;
                    } else if s1 == sigma_n {
                        t.tr[sigma][tau] = s0;
                    }
                }
            }
            t
        })
        .collect()
}

/// Orderings of up to three directions.
const PERMS_1: [[usize; 3]; 1] = [[0, 0, 0]];
const PERMS_2: [[usize; 3]; 2] = [[0, 1, 0], [1, 0, 0]];
const PERMS_3: [[usize; 3]; 6] = [
    [0, 1, 2],
    [0, 2, 1],
    [1, 0, 2],
    [1, 2, 0],
    [2, 0, 1],
    [2, 1, 0],
];

/// Where a walk from the element stands after trying to cross a sequence of its sides.
#[derive(Clone, Copy, Debug)]
struct Walk {
    /// The element reached.
    x: u32,
    /// Successful crossings (the walk stops at the first failure).
    count: u8,
    /// Current side of `x` for each starting side of the element (`u8::MAX` once its
    /// direction was crossed or where the transport is undefined).
    map: [u8; 6],
}

/// Resolves stencils against a mesh, its topology and the crossing table.
pub(crate) struct StencilResolver<'a> {
    pub mesh: &'a LinearMesh,
    pub topo: &'a Topology,
    pub transport: &'a [Cross],
}

impl StencilResolver<'_> {
    /// Try to cross starting side `side` next, as crossing number `depth` (from 1).
    #[inline]
    fn step(&self, w: &Walk, side: usize, depth: u8) -> Result<Walk, Q2Reason> {
        if w.count + 1 < depth {
            return Ok(*w); // an earlier crossing failed
        }
        let s = w.map[side];
        if s == u8::MAX {
            return Err(Q2Reason::AmbiguousStencil);
        }
        let cross = &self.transport[w.x as usize];
        let n = cross.nb[s as usize];
        if n == NONE {
            return Ok(*w);
        }
        let tr = &cross.tr[s as usize];
        let mut map = [u8::MAX; 6];
        for (m, &old) in map.iter_mut().zip(&w.map) {
            if old != u8::MAX {
                *m = tr[old as usize];
            }
        }
        Ok(Walk {
            x: n,
            count: w.count + 1,
            map,
        })
    }

    /// The entity an ordering's walk resolves to (`None` if a remaining side is not
    /// boundary), for the ordered starting sides `order`.
    fn walk_entity(&self, w: &Walk, order: &[u8]) -> Result<Option<Entity>, Q2Reason> {
        let count = w.count as usize;
        if count == order.len() {
            return Ok(Some(Entity::Cell(w.x)));
        }
        let mut sides = [0u8; 3];
        for (i, &o) in order[count..].iter().enumerate() {
            sides[i] = w.map[o as usize];
            if sides[i] == u8::MAX {
                return Err(Q2Reason::AmbiguousStencil);
            }
        }
        Ok(self.remaining_entity(w.x as usize, &sides[..order.len() - count]))
    }

    /// The boundary entity where sides `sides` of x meet, or `None` if one of them is not a
    /// boundary facet.
    fn remaining_entity(&self, x: usize, sides: &[u8]) -> Option<Entity> {
        let topo = self.topo;
        let dim = topo.dim;
        let m = masks(dim);
        let mut mask = 0xffu8;
        for &s in sides {
            if self.transport[x].nb[s as usize] != NONE {
                return None;
            }
            mask &= m[s as usize];
        }
        Some(if sides.len() == 1 {
            let f = topo.element_facet(x, sides[0] as usize);
            if dim == 3 {
                Entity::BFace(f)
            } else {
                Entity::BEdge(f)
            }
        } else if sides.len() == 2 && dim == 3 {
            Entity::BEdge(topo.element_edges[x * 12 + hex_edge_with_mask(mask)?])
        } else {
            if mask.count_ones() != 1 {
                return None;
            }
            Entity::BVertex(self.mesh.element(x)[mask.trailing_zeros() as usize])
        })
    }

    /// The packed entities of the 3^d slots of element e (x fastest), written to `out`.
    ///
    /// All walks are computed once as a tree (6 + 24 + 48 crossings for a hex): a walk
    /// crossing sides (a, b) extends the walk crossing (a).
    pub fn stencil(&self, e: usize, out: &mut [u32]) -> Result<(), Q2Reason> {
        let dim = self.topo.dim;
        let ns = 2 * dim;
        let n = net_len(dim);
        debug_assert_eq!(out.len(), n);
        let start = Walk {
            x: e as u32,
            count: 0,
            map: [0, 1, 2, 3, 4, 5],
        };
        let mut w1 = [start; 6];
        let mut w2 = [start; 36];
        let mut w3 = [start; 216];
        for a in 0..ns {
            w1[a] = self.step(&start, a, 1)?;
            for b in 0..ns {
                if b / 2 == a / 2 {
                    continue;
                }
                w2[a * 6 + b] = self.step(&w1[a], b, 2)?;
                if dim == 3 {
                    for c in 0..ns {
                        if c / 2 == a / 2 || c / 2 == b / 2 {
                            continue;
                        }
                        w3[(a * 6 + b) * 6 + c] = self.step(&w2[a * 6 + b], c, 3)?;
                    }
                }
            }
        }
        for (slot, o) in out.iter_mut().enumerate() {
            let a = [slot % 3, (slot / 3) % 3, slot / 9];
            let mut sides = [0u8; 3];
            let mut nd = 0;
            for (k, &ak) in a.iter().enumerate().take(dim) {
                if ak != 1 {
                    sides[nd] = (2 * k + ak / 2) as u8;
                    nd += 1;
                }
            }
            let perms: &[[usize; 3]] = match nd {
                0 => &[],
                1 => &PERMS_1,
                2 => &PERMS_2,
                _ => &PERMS_3,
            };
            let mut best: Option<(u8, Option<Entity>)> = None;
            for perm in perms {
                let order: [u8; 3] = std::array::from_fn(|i| sides[perm[i]]);
                let (p, q, r) = (order[0] as usize, order[1] as usize, order[2] as usize);
                let w = match nd {
                    1 => &w1[p],
                    2 => &w2[p * 6 + q],
                    _ => &w3[(p * 6 + q) * 6 + r],
                };
                let ent = self.walk_entity(w, &order[..nd])?;
                match best {
                    Some((bc, be)) if bc == w.count => {
                        if be != ent {
                            return Err(Q2Reason::AmbiguousStencil);
                        }
                    }
                    Some((bc, _)) if bc > w.count => {}
                    _ => best = Some((w.count, ent)),
                }
            }
            let ent = match best {
                None => Entity::Cell(e as u32),
                Some((_, Some(ent))) => ent,
                Some((_, None)) => return Err(Q2Reason::AmbiguousStencil),
            };
            *o = ent.pack();
        }
        let mut sorted = [0u32; 27];
        sorted[..n].copy_from_slice(out);
        sorted[..n].sort_unstable();
        if sorted[..n].windows(2).any(|w| w[0] == w[1]) {
            return Err(Q2Reason::RepeatedStencilEntry);
        }
        Ok(())
    }
}
