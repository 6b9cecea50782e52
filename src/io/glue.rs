//! Gluing the blocks of a multi-block file (CGNS zones, Plot3D grids) into one mesh.
//!
//! Input: [`Part`]s, each with its points, the corner lists of its volume cells and the
//! vertices of its outer facets. Output: one vertex numbering over all parts, vertices joined
//! either explicitly (a file's connectivity, [`Glue::join_checked`]) or where they coincide
//! ([`Glue::coincident`]).
//!
//! Invariants: two vertices are joined only if they belong to different parts and lie closer
//! than [`TOLERANCE`] times the shortest edge at either vertex (explicit joins farther apart
//! are refused with the distance), so distinct vertices of a valid mesh, which are at least an
//! edge length apart, are never merged; a merged vertex keeps the first part's position.

use std::collections::HashMap;

/// Vertices of different parts closer than this fraction of the shortest edge at them are
/// one vertex.
pub const TOLERANCE: f64 = 1e-3;

/// One block of a multi-block file.
pub struct Part<'a> {
    pub points: &'a [[f64; 3]],
    /// Corner lists of the volume cells (4 for quadrilaterals, 8 for hexahedra, VTK order).
    pub cells: Vec<&'a [usize]>,
    /// The vertices on the part's outer facets.
    pub outer: Vec<usize>,
}

/// Corner pairs of the edges of a quadrilateral (4 corners) or hexahedron (8).
fn edges(corners: usize) -> &'static [(usize, usize)] {
    const QUAD: [(usize, usize); 4] = [(0, 1), (1, 2), (2, 3), (3, 0)];
    const HEX: [(usize, usize); 12] = [
        (0, 1),
        (1, 2),
        (2, 3),
        (3, 0),
        (4, 5),
        (5, 6),
        (6, 7),
        (7, 4),
        (0, 4),
        (1, 5),
        (2, 6),
        (3, 7),
    ];
    if corners == 8 { &HEX } else { &QUAD }
}

pub fn dist(a: [f64; 3], b: [f64; 3]) -> f64 {
    ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt()
}

/// A vertex numbering over several parts, being glued.
pub struct Glue {
    offsets: Vec<usize>,
    points: Vec<[f64; 3]>,
    /// Shortest edge at each vertex (infinite where no cell touches it).
    edge: Vec<f64>,
    parent: Vec<usize>,
    /// (part, global vertex) of every outer vertex.
    outer: Vec<(usize, usize)>,
}

/// Two vertices an explicit join would merge, too far apart.
#[derive(Debug)]
pub struct Gap {
    pub gap: f64,
    pub edge: f64,
}

impl Glue {
    pub fn new(parts: &[Part<'_>]) -> Glue {
        let mut offsets = Vec::with_capacity(parts.len());
        let mut points = Vec::new();
        let mut edge = Vec::new();
        let mut outer = Vec::new();
        for (k, p) in parts.iter().enumerate() {
            let o = points.len();
            offsets.push(o);
            points.extend_from_slice(p.points);
            edge.resize(points.len(), f64::INFINITY);
            for c in &p.cells {
                for &(x, y) in edges(c.len()) {
                    let d = dist(p.points[c[x]], p.points[c[y]]);
                    for v in [c[x], c[y]] {
                        edge[o + v] = edge[o + v].min(d);
                    }
                }
            }
            outer.extend(p.outer.iter().map(|&v| (k, o + v)));
        }
        let parent = (0..points.len()).collect();
        Glue {
            offsets,
            points,
            edge,
            parent,
            outer,
        }
    }

    /// The global index of vertex `v` of part `k`.
    pub fn global(&self, k: usize, v: usize) -> usize {
        self.offsets[k] + v
    }

    fn find(&mut self, mut a: usize) -> usize {
        while self.parent[a] != a {
            self.parent[a] = self.parent[self.parent[a]];
            a = self.parent[a];
        }
        a
    }

    fn join(&mut self, a: usize, b: usize) {
        let (ra, rb) = (self.find(a), self.find(b));
        let (lo, hi) = (ra.min(rb), ra.max(rb));
        self.parent[hi] = lo;
    }

    fn tol(&self, g: usize) -> f64 {
        TOLERANCE * self.edge[g]
    }

    /// Join two global vertices a file says are one, if they coincide (module docs).
    pub fn join_checked(&mut self, a: usize, b: usize) -> Result<(), Gap> {
        let gap = dist(self.points[a], self.points[b]);
        if !(gap <= self.tol(a).max(self.tol(b))) {
            return Err(Gap {
                gap,
                edge: self.edge[a].min(self.edge[b]),
            });
        }
        self.join(a, b);
        Ok(())
    }

    /// The cell size of the spatial hash: the largest tolerance over the outer vertices.
    fn cell(&self) -> f64 {
        self.outer
            .iter()
            .map(|&(_, g)| self.tol(g))
            .filter(|t| t.is_finite() && *t > 0.0)
            .fold(0.0f64, f64::max)
    }

    /// Outer vertices of other parts within `radius(g, g2)` of each outer vertex `g`, through a
    /// spatial hash of cell size `h`: calls `visit(g, g2, distance)`.
    fn near(&self, h: f64, mut visit: impl FnMut(usize, usize, f64)) {
        if !(h > 0.0) || !h.is_finite() {
            return;
        }
        let key = |p: [f64; 3]| -> [i64; 3] { std::array::from_fn(|k| (p[k] / h).floor() as i64) };
        let mut grid: HashMap<[i64; 3], Vec<(usize, usize)>> = HashMap::new();
        let finite = |p: [f64; 3]| p.iter().all(|c| c.is_finite());
        for &(k, g) in &self.outer {
            if finite(self.points[g]) {
                grid.entry(key(self.points[g])).or_default().push((k, g));
            }
        }
        for &(k, g) in &self.outer {
            let p = self.points[g];
            if !finite(p) {
                continue;
            }
            let c = key(p);
            for dx in -1..=1 {
                for dy in -1..=1 {
                    for dz in -1..=1 {
                        let Some(cell) = grid.get(&[c[0] + dx, c[1] + dy, c[2] + dz]) else {
                            continue;
                        };
                        for &(k2, g2) in cell {
                            if k2 != k {
                                visit(g, g2, dist(p, self.points[g2]));
                            }
                        }
                    }
                }
            }
        }
    }

    /// Join the outer vertices of different parts that coincide within the tolerance.
    pub fn coincident(&mut self) {
        let h = self.cell();
        let mut pairs = Vec::new();
        self.near(h, |a, b, d| pairs.push((a, b, d)));
        for (a, b, d) in pairs {
            if d <= self.tol(a).min(self.tol(b)) {
                self.join(a, b);
            }
        }
    }

    /// The first pair of outer vertices of different parts that are not joined but lie closer
    /// than `fraction` of the shortest edge at them: a near miss, as (global a, global b,
    /// distance, edge).
    pub fn near_miss(&mut self, fraction: f64) -> Option<(usize, usize, f64, f64)> {
        let h = self
            .outer
            .iter()
            .map(|&(_, g)| fraction * self.edge[g])
            .filter(|t| t.is_finite() && *t > 0.0)
            .fold(0.0f64, f64::max);
        let mut found = None;
        let mut pairs = Vec::new();
        self.near(h, |a, b, d| pairs.push((a, b, d)));
        pairs.sort_by_key(|x| (x.0, x.1));
        for (a, b, d) in pairs {
            let e = self.edge[a].min(self.edge[b]);
            if d < fraction * e && self.find(a) != self.find(b) {
                found = Some((a, b, d, e));
                break;
            }
        }
        found
    }

    /// The part and local vertex of a global vertex.
    pub fn local(&self, g: usize) -> (usize, usize) {
        let k = self.offsets.partition_point(|&o| o <= g) - 1;
        (k, g - self.offsets[k])
    }

    /// The merged numbering: the new index of every global vertex, and the merged points
    /// (in order of first appearance).
    pub fn numbering(mut self) -> (Vec<usize>, Vec<[f64; 3]>) {
        let n = self.points.len();
        let mut id = vec![usize::MAX; n];
        let mut points = Vec::new();
        for g in 0..n {
            let r = self.find(g);
            if id[r] == usize::MAX {
                id[r] = points.len();
                points.push(self.points[r]);
            }
            id[g] = id[r];
        }
        (id, points)
    }
}

/// The cells of a structured block of `n` vertices (nk = 1 in 2D) as corner lists, flattened:
/// quadrilaterals (`cell_dim` 2) or hexahedra, corners (i,j,k), (i+1,j,k), (i+1,j+1,k),
/// (i,j+1,k), then the same at k+1; vertex (i,j,k) is i + ni (j + nj k).
pub fn structured_cells(n: [usize; 3], cell_dim: usize) -> Vec<usize> {
    let id = |i: usize, j: usize, k: usize| i + n[0] * (j + n[1] * k);
    let layers = if cell_dim == 3 { n[2] - 1 } else { 1 };
    let mut out = Vec::with_capacity((n[0] - 1) * (n[1] - 1) * layers * (1 << cell_dim));
    for k in 0..layers {
        for j in 0..n[1] - 1 {
            for i in 0..n[0] - 1 {
                out.extend([
                    id(i, j, k),
                    id(i + 1, j, k),
                    id(i + 1, j + 1, k),
                    id(i, j + 1, k),
                ]);
                if cell_dim == 3 {
                    out.extend([
                        id(i, j, k + 1),
                        id(i + 1, j, k + 1),
                        id(i + 1, j + 1, k + 1),
                        id(i, j + 1, k + 1),
                    ]);
                }
            }
        }
    }
    out
}

/// The facets of a structured block on its plane `d = c` (0-based vertex index) over the
/// cells `lo..hi` (0-based, exclusive) of the other directions, flattened (4 vertices a
/// facet in 3D, 2 in 2D).
pub fn structured_face(
    n: [usize; 3],
    cell_dim: usize,
    d: usize,
    c: usize,
    lo: [usize; 3],
    hi: [usize; 3],
) -> Vec<usize> {
    let others: Vec<usize> = (0..cell_dim).filter(|&a| a != d).collect();
    let at = |a: usize, b: usize| {
        let mut p = [0usize; 3];
        p[d] = c;
        p[others[0]] = a;
        if let Some(&o) = others.get(1) {
            p[o] = b;
        }
        p[0] + n[0] * (p[1] + n[1] * p[2])
    };
    let (b_lo, b_hi) = others.get(1).map_or((0, 1), |&o| (lo[o], hi[o]));
    let mut out = Vec::new();
    for b in b_lo..b_hi {
        for a in lo[others[0]]..hi[others[0]] {
            if cell_dim == 3 {
                out.extend([at(a, b), at(a + 1, b), at(a + 1, b + 1), at(a, b + 1)]);
            } else {
                out.extend([at(a, 0), at(a + 1, 0)]);
            }
        }
    }
    out
}
