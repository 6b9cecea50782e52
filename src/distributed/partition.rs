//! Element partition along a space-filling curve: the elements sorted by the Morton (Z-order)
//! key of their vertex-average centroid in the mesh's bounding box (ties by element index),
//! cut into `n` contiguous runs of equal length (±1).
//!
//! Input: the mesh's bounding box ([`Grid`]), the sort value ([`sort_value`]) of every element
//! on the rank that holds it, and a count of the values below given thresholds summed over
//! the ranks ([`thresholds`]). Output: the part of every element. Invariants: every element is in
//! exactly one part; part sizes differ by at most one; the result depends only on the mesh
//! (every rank computes the same partition, whichever elements it holds). Neighbouring
//! elements mostly share a part, so a part's halo (control points and entities it shares with
//! other parts) grows like its surface, not its volume.

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

/// The quantisation of the bounding box `[lo, hi]`: points map to [0, 2²¹ − 1]³.
#[derive(Clone, Copy, Debug)]
pub struct Grid {
    lo: [f64; 3],
    scale: [f64; 3],
}

impl Grid {
    pub fn new(lo: [f64; 3], hi: [f64; 3]) -> Grid {
        let scale = std::array::from_fn(|k| {
            let ext = hi[k] - lo[k];
            if ext > 0.0 {
                ((1u64 << BITS) - 1) as f64 / ext
            } else {
                0.0
            }
        });
        Grid { lo, scale }
    }

    /// Morton key of the vertex average of `corners`.
    pub fn key(&self, corners: &[[f64; 3]]) -> u64 {
        let n = corners.len().max(1) as f64;
        morton(std::array::from_fn(|k| {
            let c = corners.iter().map(|p| p[k]).sum::<f64>() / n;
            ((c - self.lo[k]) * self.scale[k]).round().max(0.0) as u64
        }))
    }
}

/// The value elements are sorted by: the Morton key, then the global element index.
pub fn sort_value(key: u64, element: u64) -> u128 {
    (key as u128) << 64 | element as u128
}

/// First sorted position of each part k = 1 … n−1 when `ne` elements are cut into `n` runs of
/// equal length (±1): ⌈k ne / n⌉, the positions where `i n / ne` steps.
fn cuts(ne: u64, n: usize) -> Vec<u64> {
    (1..n as u64)
        .map(|k| (k as u128 * ne as u128).div_ceil(n as u128) as u64)
        .collect()
}

/// The sort value at each cut (position ⌈k ne / n⌉, k = 1 … n − 1; `u128::MAX` for an
/// empty part at the end), by bisection over the 128-bit values: `count(t)` must return, for
/// each threshold candidate, how many elements of the whole mesh have a sort value ≤ it (each
/// rank counts its own and the counts are summed across ranks: 128 reductions of n − 1 counts,
/// whatever the mesh size). Element with sort value v is in part
/// `thresholds.partition_point(|&t| t <= v)`.
pub fn thresholds(ne: u64, n: usize, mut count: impl FnMut(&[u128]) -> Vec<u64>) -> Vec<u128> {
    let cuts = cuts(ne, n);
    // Invariant: the wanted value t_k (the smallest t with count(t) > cut_k) is in lo..=hi.
    let mut lo = vec![0u128; cuts.len()];
    let mut hi = vec![u128::MAX; cuts.len()];
    for _ in 0..128 {
        let mid: Vec<u128> = lo.iter().zip(&hi).map(|(&l, &h)| l + (h - l) / 2).collect();
        let c = count(&mid);
        for k in 0..cuts.len() {
            if c[k] > cuts[k] {
                hi[k] = mid[k];
            } else {
                lo[k] = mid[k] + 1;
            }
        }
    }
    lo
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::LinearMesh;

    /// The part of every element of a whole mesh: the sort values of all its elements, cut
    /// by [`thresholds`] with the counts of the whole list.
    fn parts(mesh: &LinearMesh, n: usize) -> Vec<usize> {
        let (lo, hi) = mesh.bounding_box();
        let grid = Grid::new(lo, hi);
        let npe = mesh.nodes_per_element();
        let values: Vec<u128> = (0..mesh.n_elements())
            .map(|e| sort_value(grid.key(&mesh.element_coords(e)[..npe]), e as u64))
            .collect();
        let mut sorted = values.clone();
        sorted.sort_unstable();
        let t = thresholds(values.len() as u64, n, |mid| {
            mid.iter()
                .map(|&m| sorted.partition_point(|&x| x <= m) as u64)
                .collect()
        });
        values
            .iter()
            .map(|v| t.partition_point(|&x| x <= *v))
            .collect()
    }

    #[test]
    fn morton_interleaves_bits() {
        assert_eq!(morton([1, 0, 0]), 1);
        assert_eq!(morton([0, 1, 0]), 2);
        assert_eq!(morton([0, 0, 1]), 4);
        assert_eq!(morton([3, 0, 0]), 0b1001);
        assert_eq!(morton([(1 << 21) - 1; 3]), (1u64 << 63) - 1);
    }

    /// The bisection's thresholds cut the sorted values where the serial partition does, with
    /// the counts summed over simulated ranks holding interleaved subsets, ties included.
    #[test]
    fn thresholds_cut_like_the_serial_sort() {
        let mut values: Vec<u128> = (0..1000u64)
            .map(|e| sort_value((e * 7919) % 97, e))
            .collect();
        let ranks: Vec<Vec<u128>> = (0..3)
            .map(|r| {
                let mut v: Vec<u128> = values.iter().copied().skip(r).step_by(3).collect();
                v.sort_unstable();
                v
            })
            .collect();
        values.sort_unstable();
        for n in [1, 2, 3, 4, 7, 1000, 1001] {
            let t = thresholds(values.len() as u64, n, |mid| {
                mid.iter()
                    .map(|&m| {
                        ranks
                            .iter()
                            .map(|v| v.partition_point(|&x| x <= m) as u64)
                            .sum()
                    })
                    .collect()
            });
            for (i, v) in values.iter().enumerate() {
                let part = t.partition_point(|&x| x <= *v);
                assert_eq!(part, i * n / values.len(), "n = {n}, position {i}");
            }
        }
    }

    #[test]
    fn parts_cover_the_mesh_evenly_and_are_compact() {
        let mesh = crate::mesh::generate::grid_3d(
            &crate::mesh::generate::uniform(6, 1.0),
            &crate::mesh::generate::uniform(5, 1.0),
            &crate::mesh::generate::uniform(4, 1.0),
        );
        for n in 1..=5 {
            let p = parts(&mesh, n);
            assert!(p.iter().all(|&k| k < n));
            let mut sizes = vec![0usize; n];
            for &k in &p {
                sizes[k] += 1;
            }
            let (min, max) = (sizes.iter().min().unwrap(), sizes.iter().max().unwrap());
            assert!(max - min <= 1, "{sizes:?}");
        }
        // Compactness: with 2 parts of a 6×5×4 box, far fewer facets are cut than by an
        // alternating split (every interior facet of one direction).
        let topo = crate::mesh::Topology::build(&mesh);
        let p = parts(&mesh, 2);
        let cut = topo
            .facet_elements
            .iter()
            .filter(|f| f[1] != crate::mesh::topology::NONE && p[f[0] as usize] != p[f[1] as usize])
            .count();
        assert!(cut <= 6 * 5 * 2, "{cut} facets cut");
    }
}
