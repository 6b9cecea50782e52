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
//! Invariant: distances are to the nearest point of the whole linear boundary (a bounding-volume
//! hierarchy of facet boxes finds the candidates; its branch and bound is exhaustive, so it is
//! exact up to the bilinear projection, which takes the better of a Gauss–Newton projection and
//! the four edges).

use crate::math::lagrange::lagrange_values;
use crate::math::linalg::{DVec3, box_diagonal};
use crate::mesh::HighOrderMesh;
use crate::mesh::{LinearMesh, Topology};
use rayon::prelude::*;

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

/// The glam vector of a stored point.
#[inline]
fn v(a: V3) -> DVec3 {
    DVec3::from_array(a)
}

fn segment_distance(x: V3, a: V3, b: V3) -> f64 {
    let (x, a) = (v(x), v(a));
    let ab = v(b) - a;
    let l2 = ab.dot(ab);
    let t = if l2 > 0.0 {
        ((x - a).dot(ab) / l2).clamp(0.0, 1.0)
    } else {
        0.0
    };
    (x - (a + t * ab)).length()
}

/// The unit normal of a quad with cyclic corners `c` when it is planar (corners within 10⁻¹²
/// of its diameter of one plane), oriented by its diagonals; `None` for a curved patch.
fn plane_normal(c: &[V3; 4]) -> Option<V3> {
    let (d0, d1) = (v(c[2]) - v(c[0]), v(c[3]) - v(c[1]));
    let n = d0.cross(d1);
    let nn = n.length();
    let diameter = d0.length().max(d1.length());
    if !(nn > 0.0) {
        return None;
    }
    let n = n / nn;
    let off = (1..4)
        .map(|i| n.dot(v(c[i]) - v(c[0])).abs())
        .fold(0.0, f64::max);
    (off <= 1e-12 * diameter).then_some(n.to_array())
}

/// Whether a planar quad with unit normal `n` is strictly convex (every corner turns the way
/// the diagonals' normal orients it).
fn is_convex(c: &[V3; 4], n: V3) -> bool {
    (0..4).all(|i| {
        let a = v(c[(i + 1) % 4]) - v(c[i]);
        let b = v(c[(i + 2) % 4]) - v(c[(i + 1) % 4]);
        a.cross(b).dot(v(n)) > 0.0
    })
}

/// Whether `x` projects inside the planar quad `c` with unit normal `n`: on the inner side of
/// every edge (the diagonals' normal orients a convex quad's edges all the same way; a
/// non-convex quad fails for some inside points and falls back).
fn projects_inside(x: V3, c: &[V3; 4], n: V3) -> bool {
    (0..4).all(|i| {
        let e = v(c[(i + 1) % 4]) - v(c[i]);
        e.cross(v(x) - v(c[i])).dot(v(n)) >= 0.0
    })
}

/// The distance from `x` to a planar quad when `x` projects inside it: then it is the distance
/// to the plane. `None` otherwise (a curved patch, or `x` beside the quad). Most queries are of
/// this kind (points of flat boundary faces over their own facet), and it spares them the
/// Gauss–Newton iteration.
#[cfg(test)]
fn planar_inside_distance(x: V3, c: &[V3; 4]) -> Option<f64> {
    let n = plane_normal(c)?;
    projects_inside(x, c, n).then(|| v(n).dot(v(x) - v(c[0])).abs())
}

/// Distance from `x` to the bilinear patch with cyclic corners `c`.
#[cfg(test)]
fn bilinear_distance(x: V3, c: &[V3; 4]) -> f64 {
    let plane = plane_normal(c).map(|n| (n, is_convex(c, n)));
    quad_distance(x, c, plane)
}

/// [`bilinear_distance`] given the quad's plane, when planar: its unit normal and whether it is
/// convex. Over a planar quad the distance is the plane's; beside a convex planar quad the
/// nearest point is on an edge; otherwise (curved or non-convex) the better of the edges and a
/// Gauss–Newton projection.
fn quad_distance(x: V3, c: &[V3; 4], plane: Option<(V3, bool)>) -> f64 {
    let edges = || {
        (0..4)
            .map(|i| segment_distance(x, c[i], c[(i + 1) % 4]))
            .fold(f64::INFINITY, f64::min)
    };
    if let Some((n, convex)) = plane {
        if projects_inside(x, c, n) {
            return v(n).dot(v(x) - v(c[0])).abs();
        }
        if convex {
            return edges();
        }
    }
    let s = |u: f64, w: f64| -> DVec3 {
        DVec3::from_array(std::array::from_fn(|k| {
            (1.0 - u) * (1.0 - w) * c[0][k]
                + u * (1.0 - w) * c[1][k]
                + u * w * c[2][k]
                + (1.0 - u) * w * c[3][k]
        }))
    };
    let xv = v(x);
    let mut best = edges();
    // Gauss–Newton on |S(u, v) − x|², clamped to the unit square.
    let (mut u, mut w) = (0.5, 0.5);
    for _ in 0..10 {
        let r = s(u, w) - xv;
        let su = DVec3::from_array(std::array::from_fn(|k| {
            (1.0 - w) * (c[1][k] - c[0][k]) + w * (c[2][k] - c[3][k])
        }));
        let sv = DVec3::from_array(std::array::from_fn(|k| {
            (1.0 - u) * (c[3][k] - c[0][k]) + u * (c[2][k] - c[1][k])
        }));
        let (a, b, d) = (su.dot(su), su.dot(sv), sv.dot(sv));
        let det = a * d - b * b;
        if !(det > 0.0) {
            break;
        }
        let (gu, gv) = (su.dot(r), sv.dot(r));
        let du = (d * gu - b * gv) / det;
        let dv = (a * gv - b * gu) / det;
        u = (u - du).clamp(0.0, 1.0);
        w = (w - dv).clamp(0.0, 1.0);
        best = best.min((s(u, w) - xv).length());
        if du.abs() + dv.abs() < 1e-14 {
            break;
        }
    }
    best
}

/// The input's linear boundary in a bounding-volume hierarchy of facet boxes.
///
/// A uniform grid fails on the meshes this is for: a CFD domain's far field is 10⁴–10⁷ times
/// the wall cells, so one grid cell around the wall holds thousands of facets (and a one-layer
/// extrusion's two side planes hold every element's face) and each query scanned them all.
/// The hierarchy's boxes shrink with the facets, so a query visits O(log n) boxes.
struct BoundaryTree<'a> {
    mesh: &'a LinearMesh,
    facets: Vec<&'a [u32]>,
    /// Each facet's box: a lower bound of its distance, checked before computing it.
    boxes: Vec<(V3, V3)>,
    /// Each quad facet's plane when planar: unit normal and convexity ([`quad_distance`]).
    planes: Vec<Option<(V3, bool)>>,
    /// Nodes in depth-first order; node 0 is the root.
    nodes: Vec<TreeNode>,
    /// Facet ids, permuted so that every node's facets are contiguous.
    order: Vec<u32>,
}

/// A node of [`BoundaryTree`]: its box, and either two children or a range of `order`.
struct TreeNode {
    bounds: (V3, V3),
    /// Leaf: `order[start..end]`; inner node: `end == 0` and its children are `start` and
    /// `start + 1`.
    start: u32,
    end: u32,
}

/// Facets per leaf.
const LEAF: usize = 4;

/// Distance from `x` to the box (lo, hi) (0 inside): a lower bound of the distance to
/// anything inside it.
fn box_distance(x: V3, (lo, hi): &(V3, V3)) -> f64 {
    let d: V3 = std::array::from_fn(|k| (lo[k] - x[k]).max(x[k] - hi[k]).max(0.0));
    v(d).length()
}

fn union(a: (V3, V3), b: &(V3, V3)) -> (V3, V3) {
    (
        std::array::from_fn(|k| a.0[k].min(b.0[k])),
        std::array::from_fn(|k| a.1[k].max(b.1[k])),
    )
}

const EMPTY_BOX: (V3, V3) = ([f64::INFINITY; 3], [f64::NEG_INFINITY; 3]);

impl<'a> BoundaryTree<'a> {
    /// The tree of the topology facets `facets` (the whole boundary: `topo.boundary_facets`).
    fn new(mesh: &'a LinearMesh, topo: &'a Topology, facets: &[u32]) -> Self {
        let facets: Vec<&[u32]> = facets
            .iter()
            .map(|&f| topo.facet_vertices(f as usize))
            .collect();
        let boxes: Vec<(V3, V3)> = facets
            .iter()
            .map(|f| {
                f.iter().fold(EMPTY_BOX, |b, &v| {
                    let x = mesh.coords[v as usize];
                    union(b, &(x, x))
                })
            })
            .collect();
        let mut order: Vec<u32> = (0..facets.len() as u32).collect();
        let mut nodes = Vec::with_capacity(2 * facets.len() / LEAF + 1);
        if !facets.is_empty() {
            nodes.push(TreeNode {
                bounds: EMPTY_BOX,
                start: 0,
                end: 0,
            });
            Self::split(&boxes, &mut order, 0, 0, &mut nodes);
        }
        let planes = facets
            .iter()
            .map(|f| {
                let c: [V3; 4] = std::array::from_fn(|i| mesh.coords[f[i % f.len()] as usize]);
                let n = plane_normal(&c).filter(|_| f.len() == 4)?;
                Some((n, is_convex(&c, n)))
            })
            .collect();
        BoundaryTree {
            mesh,
            facets,
            boxes,
            planes,
            nodes,
            order,
        }
    }

    /// Fill node `at` with the facets `order[start..start + len]`: a leaf when few, else split
    /// at the median of the box centres along the widest axis of the centres.
    fn split(
        boxes: &[(V3, V3)],
        order: &mut [u32],
        offset: usize,
        at: usize,
        nodes: &mut Vec<TreeNode>,
    ) {
        let bounds = order
            .iter()
            .fold(EMPTY_BOX, |b, &f| union(b, &boxes[f as usize]));
        nodes[at].bounds = bounds;
        if order.len() <= LEAF {
            nodes[at].start = offset as u32;
            nodes[at].end = (offset + order.len()) as u32;
            return;
        }
        let centre = |f: u32, k: usize| {
            let (a, b) = &boxes[f as usize];
            a[k] + b[k]
        };
        let spread = |k: usize| {
            let (lo, hi) = order
                .iter()
                .fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), &f| {
                    (l.min(centre(f, k)), h.max(centre(f, k)))
                });
            hi - lo
        };
        let axis = (0..3)
            .max_by(|&a, &b| spread(a).total_cmp(&spread(b)))
            .unwrap_or(0);
        let mid = order.len() / 2;
        order.select_nth_unstable_by(mid, |&a, &b| centre(a, axis).total_cmp(&centre(b, axis)));
        let child = nodes.len();
        nodes[at].start = child as u32;
        for _ in 0..2 {
            nodes.push(TreeNode {
                bounds: EMPTY_BOX,
                start: 0,
                end: 0,
            });
        }
        let (left, right) = order.split_at_mut(mid);
        Self::split(boxes, left, offset, child, nodes);
        Self::split(boxes, right, offset + mid, child + 1, nodes);
    }

    fn facet_distance(&self, x: V3, f: usize) -> f64 {
        let c = |i: usize| self.mesh.coords[self.facets[f][i] as usize];
        if self.facets[f].len() == 2 {
            segment_distance(x, c(0), c(1))
        } else {
            quad_distance(x, &[c(0), c(1), c(2), c(3)], self.planes[f])
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
        if d <= 1e-12 * self.scale() {
            d
        } else {
            self.distance_below(x, d)
        }
    }

    /// Largest extent of the boundary's box.
    fn scale(&self) -> f64 {
        self.nodes.first().map_or(0.0, |n| {
            (0..3)
                .map(|k| n.bounds.1[k] - n.bounds.0[k])
                .fold(0.0, f64::max)
        })
    }

    /// Distance from `x` to the linear boundary, given an upper bound `best` of it: depth-first
    /// branch and bound, nearer child first, skipping boxes no nearer than the best so far.
    fn distance_below(&self, x: V3, mut best: f64) -> f64 {
        if self.nodes.is_empty() {
            return 0.0;
        }
        let mut stack: Vec<(f64, u32)> = vec![(box_distance(x, &self.nodes[0].bounds), 0)];
        while let Some((d, at)) = stack.pop() {
            if d >= best {
                continue;
            }
            let node = &self.nodes[at as usize];
            if node.end > 0 {
                for &f in &self.order[node.start as usize..node.end as usize] {
                    if box_distance(x, &self.boxes[f as usize]) < best {
                        best = best.min(self.facet_distance(x, f as usize));
                    }
                }
                continue;
            }
            let (a, b) = (node.start, node.start + 1);
            let da = box_distance(x, &self.nodes[a as usize].bounds);
            let db = box_distance(x, &self.nodes[b as usize].bounds);
            // Pushed far first, so the near child is searched first and tightens `best`.
            if da <= db {
                stack.push((db, b));
                stack.push((da, a));
            } else {
                stack.push((da, a));
                stack.push((db, b));
            }
        }
        best
    }
}

/// Bounding-box diagonal of `mesh` (positive).
fn diagonal(mesh: &LinearMesh) -> f64 {
    let (lo, hi) = mesh.bounding_box();
    box_diagonal(lo, hi)
}

/// Vertex deviation alone: (max, rms) distance of the output's boundary vertex nodes from the
/// input vertices, relative to the bounding-box diagonal.
pub fn vertex_deviation(mesh: &LinearMesh, topo: &Topology, ho: &HighOrderMesh) -> (f64, f64) {
    let diagonal = diagonal(mesh);
    let (mut max, mut sum, mut n) = (0.0f64, 0.0, 0usize);
    for (v, &b) in topo.vertex_on_boundary.iter().enumerate() {
        if b {
            let d = (DVec3::from_array(mesh.coords[v]) - DVec3::from_array(ho.nodes[v])).length()
                / diagonal;
            max = max.max(d);
            sum += d * d;
            n += 1;
        }
    }
    (max, if n > 0 { (sum / n as f64).sqrt() } else { 0.0 })
}

/// The largest distances (absolute: node, sample; see the module docs) of the boundary facets
/// of `ho` from the linear boundary made of the topology facets `facets` of `mesh`: output
/// facet i lies over `facets[over[i]]` (`usize::MAX`: unknown). A share of a mesh passes the
/// facets of its sub-mesh that are boundary facets of the whole mesh, around its own ones.
pub fn facet_distances(
    mesh: &LinearMesh,
    topo: &Topology,
    facets: &[u32],
    ho: &HighOrderMesh,
    over: &[usize],
) -> (f64, f64) {
    let grid = BoundaryTree::new(mesh, topo, facets);
    let npf = ho.nodes_per_facet();
    let own = |f: usize| over[f];
    // Facet points on the lattice of order 2p (p = 1: the midpoints too). The even lattice
    // points are the facet's nodes (the Lagrange basis is exactly 1 and 0 there, so the
    // interpolated point is the node itself), so one pass gives both maxima.
    let p = ho.order;
    let q = 2 * p;
    let basis: Vec<Vec<f64>> = (0..=q)
        .map(|i| lagrange_values(p, i as f64 / q as f64))
        .collect();
    let facet_dim = ho.dim - 1;
    let (node_max, sample_max) = ho
        .boundary
        .par_chunks(npf)
        .enumerate()
        .map(|(facet, f)| {
            let (mut node, mut sample) = (0.0f64, 0.0f64);
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
                    let d = grid.distance_from(x, own(facet));
                    sample = sample.max(d);
                    if i % 2 == 0 && j % 2 == 0 {
                        node = node.max(d);
                    }
                }
            }
            (node, sample)
        })
        .reduce(|| (0.0, 0.0), |a, b| (a.0.max(b.0), a.1.max(b.1)));
    (node_max, sample_max)
}

/// The three measures of `ho` against the input `mesh` (see the module docs).
pub fn boundary_deviation(
    mesh: &LinearMesh,
    topo: &Topology,
    ho: &HighOrderMesh,
) -> BoundaryDeviation {
    let diagonal = diagonal(mesh);
    let (vertex_max, vertex_rms) = vertex_deviation(mesh, topo, ho);
    // Output boundary facet f lies over input boundary facet f (both in the topology's order),
    // unless the output was subdivided: then every facet is searched for from scratch.
    let over: Vec<usize> = if ho.n_boundary() == topo.boundary_facets.len() {
        (0..ho.n_boundary()).collect()
    } else {
        vec![usize::MAX; ho.n_boundary()]
    };
    let (node_max, sample_max) = facet_distances(mesh, topo, &topo.boundary_facets, ho, &over);
    let (node_max, sample_max) = (node_max / diagonal, sample_max / diagonal);
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
        // A tilted planar trapezoid: the fast path (over the inside) and the iteration (beside
        // it) against the nearest of a fine sampling of the patch.
        let trap = [
            [0.0, 0.0, 0.0],
            [1.0, 0.0, 0.5],
            [2.0, 2.0, 1.5],
            [0.0, 2.0, 0.5],
        ];
        let n = 400;
        for x in [
            [0.5, 1.0, 3.0],
            [0.3, 0.2, -1.0],
            [3.0, 1.0, 0.0],
            [-1.0, -1.0, 2.0],
        ] {
            let mut sampled = f64::INFINITY;
            for i in 0..=n {
                for j in 0..=n {
                    let (u, v) = (i as f64 / n as f64, j as f64 / n as f64);
                    let p: V3 = std::array::from_fn(|k| {
                        (1.0 - u) * (1.0 - v) * trap[0][k]
                            + u * (1.0 - v) * trap[1][k]
                            + u * v * trap[2][k]
                            + (1.0 - u) * v * trap[3][k]
                    });
                    sampled = sampled.min((DVec3::from_array(x) - DVec3::from_array(p)).length());
                }
            }
            let d = bilinear_distance(x, &trap);
            assert!(d <= sampled + 1e-12 && d > sampled - 1e-4, "{d} {sampled}");
        }
        assert!(planar_inside_distance([0.5, 1.0, 3.0], &trap).is_some());
        assert!(planar_inside_distance([3.0, 1.0, 0.0], &trap).is_none());
    }

    /// The tree's branch and bound against every facet, on a graded grid (facets from 10⁻⁴
    /// to 1) and on a torus (curved, every facet a twisted patch), at points inside, outside
    /// and far away.
    #[test]
    fn tree_search_matches_exhaustive_search() {
        use crate::mesh::generate::{butterfly_disc, grid_3d, revolve};
        let graded: Vec<f64> = (0..12)
            .map(|i| if i == 0 { 0.0 } else { 1e-4 * 2.3f64.powi(i) })
            .collect();
        let meshes = [
            grid_3d(&graded, &[0.0, 0.5, 1.0, 3.0], &[0.0, 1e-3, 1.0]),
            revolve(&butterfly_disc(3, 2), 3.0, 24),
        ];
        for mesh in &meshes {
            let topo = Topology::build(mesh);
            let tree = BoundaryTree::new(mesh, &topo, &topo.boundary_facets);
            let (lo, hi) = mesh.bounding_box();
            let mut seed = 12345u64;
            let mut rand = || {
                seed = seed
                    .wrapping_mul(6364136223846793005)
                    .wrapping_add(1442695040888963407);
                (seed >> 11) as f64 / (1u64 << 53) as f64
            };
            for _ in 0..500 {
                let x: V3 = std::array::from_fn(|k| {
                    let w = hi[k] - lo[k];
                    lo[k] - w + 3.0 * w * rand().powi(3)
                });
                let exhaustive = (0..tree.facets.len())
                    .map(|f| tree.facet_distance(x, f))
                    .fold(f64::INFINITY, f64::min);
                // Equal up to rounding (a box distance may exceed a facet's by an ulp).
                let tol = 1e-12 * (1.0 + exhaustive);
                assert!((tree.distance_below(x, f64::INFINITY) - exhaustive).abs() <= tol);
                let own = (rand() * tree.facets.len() as f64) as usize;
                assert!((tree.distance_from(x, own) - exhaustive).abs() <= tol);
            }
        }
    }
}
