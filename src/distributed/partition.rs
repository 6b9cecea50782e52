//! Element partition along a space-filling curve: the elements sorted by the Morton (Z-order)
//! key of their vertex-average centroid in the mesh's bounding box, cut into `n` contiguous
//! runs of equal length (±1).
//!
//! Input: a linear mesh and the number of parts. Output: the part of every element
//! ([`Partition::part`]) and each part's elements in curve order. Invariants: every element is
//! in exactly one part; part sizes differ by at most one; the result depends only on the mesh
//! (every rank computes the same partition). Neighbouring elements mostly share a part, so a
//! part's halo (control points and entities it shares with other parts) grows like its
//! surface, not its volume.

use crate::mesh::LinearMesh;

/// The part of every element and the elements of every part.
#[derive(Clone, Debug)]
pub struct Partition {
    /// Part of each element.
    pub part: Vec<u32>,
    /// Elements of each part, in increasing element order.
    pub elements: Vec<Vec<usize>>,
}

/// Bits per axis of the Morton key (3 × 21 = 63 bits).
const BITS: u32 = 21;

/// Spread the low 21 bits of `x` to every third bit.
fn spread(mut x: u64) -> u64 {
    x &= (1 << BITS) - 1;
    x = (x | x << 32) & 0x1f00000000ffff;
    x = (x | x << 16) & 0x1f0000ff0000ff;
    x = (x | x << 8) & 0x100f00f00f00f00f;
    x = (x | x << 4) & 0x10c30c30c30c30c3;
    x = (x | x << 2) & 0x1249249249249249;
    x
}

/// Morton key of a point with coordinates quantised in [0, 1]³.
pub fn morton(q: [u64; 3]) -> u64 {
    spread(q[0]) | spread(q[1]) << 1 | spread(q[2]) << 2
}

impl Partition {
    /// Partition `mesh`'s elements into `n` parts (n ≥ 1).
    pub fn morton(mesh: &LinearMesh, n: usize) -> Partition {
        assert!(n >= 1, "at least one part");
        let (lo, hi) = mesh.bounding_box();
        let npe = mesh.nodes_per_element();
        let scale: [f64; 3] = std::array::from_fn(|k| {
            let ext = hi[k] - lo[k];
            if ext > 0.0 {
                ((1u64 << BITS) - 1) as f64 / ext
            } else {
                0.0
            }
        });
        let mut keyed: Vec<(u64, usize)> = (0..mesh.n_elements())
            .map(|e| {
                let x = mesh.element_coords(e);
                let q = std::array::from_fn(|k| {
                    let c = x[..npe].iter().map(|p| p[k]).sum::<f64>() / npe as f64;
                    ((c - lo[k]) * scale[k]).round().max(0.0) as u64
                });
                (morton(q), e)
            })
            .collect();
        keyed.sort_unstable();
        let ne = keyed.len();
        let mut part = vec![0u32; ne];
        let mut elements = vec![Vec::new(); n];
        for (i, &(_, e)) in keyed.iter().enumerate() {
            let p = i * n / ne.max(1);
            part[e] = p as u32;
            elements[p].push(e);
        }
        for list in &mut elements {
            list.sort_unstable();
        }
        Partition { part, elements }
    }

    pub fn n_parts(&self) -> usize {
        self.elements.len()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn morton_interleaves_bits() {
        assert_eq!(morton([1, 0, 0]), 1);
        assert_eq!(morton([0, 1, 0]), 2);
        assert_eq!(morton([0, 0, 1]), 4);
        assert_eq!(morton([3, 0, 0]), 0b1001);
        assert_eq!(morton([(1 << 21) - 1; 3]), (1u64 << 63) - 1);
    }

    #[test]
    fn parts_cover_the_mesh_evenly_and_are_compact() {
        let mesh = crate::mesh::generate::grid_3d(
            &crate::mesh::generate::uniform(6, 1.0),
            &crate::mesh::generate::uniform(5, 1.0),
            &crate::mesh::generate::uniform(4, 1.0),
        );
        for n in 1..=5 {
            let p = Partition::morton(&mesh, n);
            let mut seen = vec![0; mesh.n_elements()];
            for (k, list) in p.elements.iter().enumerate() {
                for &e in list {
                    seen[e] += 1;
                    assert_eq!(p.part[e] as usize, k);
                }
            }
            assert!(seen.iter().all(|&s| s == 1));
            let sizes: Vec<usize> = p.elements.iter().map(Vec::len).collect();
            let (min, max) = (sizes.iter().min().unwrap(), sizes.iter().max().unwrap());
            assert!(max - min <= 1, "{sizes:?}");
        }
        // Compactness: with 2 parts of a 6×5×4 box, far fewer facets are cut than by an
        // alternating split (every interior facet of one direction).
        let topo = crate::mesh::Topology::build(&mesh);
        let p = Partition::morton(&mesh, 2);
        let cut = topo
            .facet_elements
            .iter()
            .filter(|f| {
                f[1] != crate::mesh::topology::NONE
                    && p.part[f[0] as usize] != p.part[f[1] as usize]
            })
            .count();
        assert!(cut <= 6 * 5 * 2, "{cut} facets cut");
    }
}
