//! How far the curving moved the boundary, measured three ways for the report.
//!
//! Inputs: the linear input mesh with its topology and the written high-order mesh (whose
//! first node ids are the input's vertex ids). Outputs, all relative to the input's
//! bounding-box diagonal (also returned, for absolute values):
//! * **vertex deviation**: distance of each output vertex node on the boundary from its input
//!   vertex (max and rms). It is 0 where `--snap-boundary` snapped, whatever the rest does.
//! * **node distance**: distance of *every* written boundary node (vertex, edge and face
//!   nodes) from the input's linear boundary, the union of its straight edges (2D) or bilinear
//!   faces (3D). On a convex curved wall the edge nodes sit outside the chords: this is how far
//!   the curved wall stands off the linear one at the nodes a solver reads.
//! * **sample distance**: the same at the points of the output's boundary facets on a lattice
//!   twice as fine as the nodes (the facet's Lagrange interpolant), so between nodes too.
//!
//! Invariant: distances are to the nearest point of the whole linear boundary (a uniform grid
//! of facet boxes finds the candidates; an exhaustive ring search makes it exact up to the
//! bilinear projection, which takes the better of a Gauss–Newton projection and the four edges).

use crate::mesh::{LinearMesh, Topology};
use crate::sample::HighOrderMesh;
use rayon::prelude::*;
use std::collections::HashMap;

/// The three measures (relative to `diagonal`).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct BoundaryDeviation {
    /// Bounding-box diagonal of the input.
    pub diagonal: f64,
    pub vertex_max: f64,
    pub vertex_rms: f64,
    pub node_max: f64,
    pub sample_max: f64,
}

type V3 = [f64; 3];

fn sub(a: V3, b: V3) -> V3 {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}
fn dot(a: V3, b: V3) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}
fn norm(a: V3) -> f64 {
    dot(a, a).sqrt()
}

fn segment_distance(x: V3, a: V3, b: V3) -> f64 {
    let ab = sub(b, a);
    let l2 = dot(ab, ab);
    let t = if l2 > 0.0 {
        (dot(sub(x, a), ab) / l2).clamp(0.0, 1.0)
    } else {
        0.0
    };
    norm(sub(
        x,
        [a[0] + t * ab[0], a[1] + t * ab[1], a[2] + t * ab[2]],
    ))
}

/// Distance from `x` to the bilinear patch with cyclic corners `c`.
fn bilinear_distance(x: V3, c: &[V3; 4]) -> f64 {
    let s = |u: f64, v: f64| -> V3 {
        std::array::from_fn(|k| {
            (1.0 - u) * (1.0 - v) * c[0][k]
                + u * (1.0 - v) * c[1][k]
                + u * v * c[2][k]
                + (1.0 - u) * v * c[3][k]
        })
    };
    let mut best = (0..4)
        .map(|i| segment_distance(x, c[i], c[(i + 1) % 4]))
        .fold(f64::INFINITY, f64::min);
    // Gauss–Newton on |S(u, v) − x|², clamped to the unit square.
    let (mut u, mut v) = (0.5, 0.5);
    for _ in 0..10 {
        let r = sub(s(u, v), x);
        let su: V3 =
            std::array::from_fn(|k| (1.0 - v) * (c[1][k] - c[0][k]) + v * (c[2][k] - c[3][k]));
        let sv: V3 =
            std::array::from_fn(|k| (1.0 - u) * (c[3][k] - c[0][k]) + u * (c[2][k] - c[1][k]));
        let (a, b, d) = (dot(su, su), dot(su, sv), dot(sv, sv));
        let det = a * d - b * b;
        if !(det > 0.0) {
            break;
        }
        let (gu, gv) = (dot(su, r), dot(sv, r));
        let du = (d * gu - b * gv) / det;
        let dv = (a * gv - b * gu) / det;
        u = (u - du).clamp(0.0, 1.0);
        v = (v - dv).clamp(0.0, 1.0);
        best = best.min(norm(sub(s(u, v), x)));
        if du.abs() + dv.abs() < 1e-14 {
            break;
        }
    }
    best
}

/// The input's linear boundary in a uniform grid of facet bounding boxes.
struct BoundaryGrid<'a> {
    mesh: &'a LinearMesh,
    facets: Vec<&'a [u32]>,
    lo: V3,
    h: f64,
    cells: HashMap<[i64; 3], Vec<u32>>,
    /// Bounding box of each facet: a cheap lower bound of its distance, so only facets that
    /// could be nearer than the best so far are measured.
    boxes: Vec<(V3, V3)>,
    /// Grid extent in cells (bounds the ring search).
    span: i64,
}

/// Distance from `x` to the box (lo, hi) (0 inside).
fn box_distance(x: V3, (lo, hi): &(V3, V3)) -> f64 {
    let d: V3 = std::array::from_fn(|k| (lo[k] - x[k]).max(x[k] - hi[k]).max(0.0));
    norm(d)
}

impl<'a> BoundaryGrid<'a> {
    fn new(mesh: &'a LinearMesh, topo: &'a Topology) -> Self {
        let facets: Vec<&[u32]> = topo
            .boundary_facets
            .iter()
            .map(|&f| topo.facet_vertices(f as usize))
            .collect();
        let (lo, hi) = mesh.bounding_box();
        let boxes: Vec<(V3, V3)> = facets
            .iter()
            .map(|f| {
                let mut a = [f64::INFINITY; 3];
                let mut b = [f64::NEG_INFINITY; 3];
                for &v in f.iter() {
                    let x = mesh.coords[v as usize];
                    for k in 0..3 {
                        a[k] = a[k].min(x[k]);
                        b[k] = b[k].max(x[k]);
                    }
                }
                (a, b)
            })
            .collect();
        let mean_size = boxes
            .iter()
            .map(|(a, b)| (0..3).map(|k| b[k] - a[k]).fold(0.0, f64::max))
            .sum::<f64>()
            / boxes.len().max(1) as f64;
        let extent = (0..3).map(|k| hi[k] - lo[k]).fold(0.0, f64::max);
        // At most ~200 cells across the mesh: with facets of very different sizes (a cone's tip
        // and base) the mean size would put a large facet into millions of cells.
        let h = if mean_size > 0.0 {
            mean_size.max(extent / 200.0)
        } else {
            extent.max(1.0)
        };
        let cell =
            |x: V3| -> [i64; 3] { std::array::from_fn(|k| ((x[k] - lo[k]) / h).floor() as i64) };
        let mut cells: HashMap<[i64; 3], Vec<u32>> = HashMap::new();
        for (i, (a, b)) in boxes.iter().enumerate() {
            let (ca, cb) = (cell(*a), cell(*b));
            for i0 in ca[0]..=cb[0] {
                for i1 in ca[1]..=cb[1] {
                    for i2 in ca[2]..=cb[2] {
                        cells.entry([i0, i1, i2]).or_default().push(i as u32);
                    }
                }
            }
        }
        let span = (extent / h) as i64 + 2;
        BoundaryGrid {
            mesh,
            facets,
            lo,
            h,
            cells,
            boxes,
            span,
        }
    }

    fn facet_distance(&self, x: V3, f: usize) -> f64 {
        let c = |i: usize| self.mesh.coords[self.facets[f][i] as usize];
        if self.facets[f].len() == 2 {
            segment_distance(x, c(0), c(1))
        } else {
            bilinear_distance(x, &[c(0), c(1), c(2), c(3)])
        }
    }

    /// Distance from `x`, a point of the output facet over input facet `own`, to the linear
    /// boundary: its own facet's distance bounds the search.
    fn distance_from(&self, x: V3, own: usize) -> f64 {
        if own >= self.facets.len() {
            // Subdivided output: its facets no longer map one to one onto the input's.
            return self.distance_below(x, f64::INFINITY);
        }
        let d = self.facet_distance(x, own);
        // On its own facet to rounding: no other facet can be meaningfully nearer.
        if d <= 1e-12 * self.h {
            d
        } else {
            self.distance_below(x, d)
        }
    }

    /// Distance from `x` to the linear boundary, given an upper bound `best` of it.
    fn distance_below(&self, x: V3, mut best: f64) -> f64 {
        if self.facets.is_empty() {
            return 0.0;
        }
        let c: [i64; 3] = std::array::from_fn(|k| ((x[k] - self.lo[k]) / self.h).floor() as i64);
        // Facets outside the rings searched so far are at least r·h away.
        let far = c.iter().map(|v| v.abs()).max().unwrap_or(0) + self.span;
        for r in 0..=far {
            for i0 in -r..=r {
                for i1 in -r..=r {
                    for i2 in -r..=r {
                        if i0.abs().max(i1.abs()).max(i2.abs()) != r {
                            continue;
                        }
                        if let Some(list) = self.cells.get(&[c[0] + i0, c[1] + i1, c[2] + i2]) {
                            for &f in list {
                                if box_distance(x, &self.boxes[f as usize]) < best {
                                    best = best.min(self.facet_distance(x, f as usize));
                                }
                            }
                        }
                    }
                }
            }
            if best <= r as f64 * self.h {
                break;
            }
        }
        best
    }
}

/// Lagrange basis on the equispaced nodes i/p of [0, 1], at `t`.
fn lagrange_1d(p: usize, t: f64) -> Vec<f64> {
    (0..=p)
        .map(|i| {
            let ti = i as f64 / p as f64;
            (0..=p)
                .filter(|&j| j != i)
                .map(|j| {
                    let tj = j as f64 / p as f64;
                    (t - tj) / (ti - tj)
                })
                .product()
        })
        .collect()
}

/// Bounding-box diagonal of `mesh` (positive).
fn diagonal(mesh: &LinearMesh) -> f64 {
    let (lo, hi) = mesh.bounding_box();
    norm(sub(hi, lo)).max(f64::MIN_POSITIVE)
}

/// Vertex deviation alone: (max, rms) distance of the output's boundary vertex nodes from the
/// input vertices, relative to the bounding-box diagonal.
pub fn vertex_deviation(mesh: &LinearMesh, topo: &Topology, ho: &HighOrderMesh) -> (f64, f64) {
    let diagonal = diagonal(mesh);
    let (mut max, mut sum, mut n) = (0.0f64, 0.0, 0usize);
    for (v, &b) in topo.vertex_on_boundary.iter().enumerate() {
        if b {
            let d = norm(sub(mesh.coords[v], ho.nodes[v])) / diagonal;
            max = max.max(d);
            sum += d * d;
            n += 1;
        }
    }
    (max, if n > 0 { (sum / n as f64).sqrt() } else { 0.0 })
}

/// The three measures of `ho` against the input `mesh` (see the module docs).
pub fn boundary_deviation(
    mesh: &LinearMesh,
    topo: &Topology,
    ho: &HighOrderMesh,
) -> BoundaryDeviation {
    let diagonal = diagonal(mesh);
    let (vertex_max, vertex_rms) = vertex_deviation(mesh, topo, ho);
    let grid = BoundaryGrid::new(mesh, topo);
    // Output boundary facet f lies over input boundary facet f (both in the topology's order),
    // unless the output was subdivided: then every facet is searched for from scratch.
    let npf = ho.nodes_per_facet();
    let own = |f: usize| {
        if ho.n_boundary() == topo.boundary_facets.len() {
            f
        } else {
            usize::MAX
        }
    };
    let node_max = ho
        .boundary
        .par_chunks(npf)
        .enumerate()
        .map(|(f, nodes)| {
            nodes
                .iter()
                .map(|&n| grid.distance_from(ho.nodes[n as usize], own(f)))
                .fold(0.0, f64::max)
        })
        .reduce(|| 0.0, f64::max)
        / diagonal;

    // Facet points on the lattice of order 2p (p = 1: the midpoints too).
    let p = ho.order;
    let q = 2 * p;
    let basis: Vec<Vec<f64>> = (0..=q)
        .map(|i| lagrange_1d(p, i as f64 / q as f64))
        .collect();
    let facet_dim = ho.dim - 1;
    let sample_max = ho
        .boundary
        .par_chunks(npf)
        .enumerate()
        .map(|(facet, f)| {
            let mut m = 0.0f64;
            let second = if facet_dim == 2 { q } else { 0 };
            for j in 0..=second {
                for i in 0..=q {
                    let mut x = [0.0; 3];
                    for (s, &node) in f.iter().enumerate() {
                        let (a, b) = (s % (p + 1), s / (p + 1));
                        let w = if facet_dim == 2 {
                            basis[i][a] * basis[j][b]
                        } else {
                            basis[i][s]
                        };
                        if w != 0.0 {
                            let y = ho.nodes[node as usize];
                            for k in 0..3 {
                                x[k] += w * y[k];
                            }
                        }
                    }
                    m = m.max(grid.distance_from(x, own(facet)));
                }
            }
            m
        })
        .reduce(|| 0.0, f64::max)
        / diagonal;
    BoundaryDeviation {
        diagonal,
        vertex_max,
        vertex_rms,
        node_max,
        sample_max,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn distances_to_segments_and_patches() {
        assert!((segment_distance([0.5, 1.0, 0.0], [0.0; 3], [1.0, 0.0, 0.0]) - 1.0).abs() < 1e-15);
        assert!((segment_distance([2.0, 0.0, 0.0], [0.0; 3], [1.0, 0.0, 0.0]) - 1.0).abs() < 1e-15);
        let sq = [
            [0.0, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [1.0, 1.0, 0.0],
            [0.0, 1.0, 0.0],
        ];
        assert!((bilinear_distance([0.3, 0.6, 0.25], &sq) - 0.25).abs() < 1e-14);
        assert!((bilinear_distance([2.0, 0.5, 0.0], &sq) - 1.0).abs() < 1e-14);
        // A twisted patch: the hyperbolic paraboloid z = (2u−1)(2v−1)/4 over the unit square
        // passes through (0.5, 0.5, 0).
        let twisted = [
            [0.0, 0.0, 0.25],
            [1.0, 0.0, -0.25],
            [1.0, 1.0, 0.25],
            [0.0, 1.0, -0.25],
        ];
        assert!(bilinear_distance([0.5, 0.5, 0.0], &twisted) < 1e-14);
    }

    #[test]
    fn lagrange_basis_interpolates() {
        for p in 1..=6 {
            for i in 0..=p {
                let b = lagrange_1d(p, i as f64 / p as f64);
                for (j, v) in b.iter().enumerate() {
                    assert!((v - (i == j) as u8 as f64).abs() < 1e-12);
                }
            }
        }
    }
}
