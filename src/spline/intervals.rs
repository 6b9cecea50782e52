//! Non-uniform knot intervals of the spline elements (`knot-intervals.md`): the ratios of
//! neighbouring cells' knot intervals, so that a graded grid is exactly representable.
//!
//! Input: a [`LinearMesh`], its [`Topology`] and [`KnotParams`]. Output: per element and
//! direction k the two weights `[α, β]` of the 1D Bézier extraction rows
//! ([`super::Op1d::bernstein_matrix_graded`]): `α = h₀/(h₋₁+h₀)`, `β = h₁/(h₀+h₁)` with `h₀`
//! the element's interval in direction k and `h₋₁`, `h₁` its neighbours' across the faces at
//! t = 0 and t = 1. Uniform knots are `α = β = ½`.
//!
//! Only ratios of intervals enter the rows, so what is assigned is one log-ratio
//! `ρ = ln(h_B / h_A)` per **knot surface**: the facets between two layers of cells, continued
//! across regular elements (facet F of element E and the facet of E's neighbour E' that
//! meets F along the face E and E' share belong to the same knot surface). Every basis
//! function shared by two spline elements then sees the same ratios in both, so the map stays
//! C¹ (any value per surface is consistent). The value is the mean, over the surface's
//! interior facets weighted by 1 / facet size (length in 2D, area in 3D), of the measured
//! `ln(extent_B / extent_A)`, the extents taken across the facet between opposite face
//! centres; the weight lets the thin cells of a boundary layer, which a misfit ratio distorts
//! most, decide the ratio where a surface crosses the layer: the geometric grading of a boundary layer is one ratio
//! per layer crossing, whatever the cells' size along the layer (an O-grid's cells grow along
//! the layer; their ratios across it do not), and a surface wandering through an unstructured
//! region averages to nearly uniform.
//!
//! Invariants: the weights lie in `[1/(1+r), r/(1+r)]` with `r` = [`KnotParams::max_ratio`];
//! a tensor-product grid (any spacing per direction) under an affine map gets exactly its
//! spacing ratios, so the initial spline map (control points at cell centres, Greville
//! abscissae) equals the straight map; the result depends only on topology and coordinates.
//! Surfaces closing on themselves with opposite orientation (non-orientable continuation) get
//! uniform knots.

use crate::mesh::LinearMesh;
use crate::mesh::topology::{NONE, Topology};
use crate::params::{ParamError, above};
use rayon::prelude::*;
use serde::Serialize;

/// How the knot intervals of the spline elements are chosen.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum KnotIntervals {
    /// Every interval 1 (the paper's construction).
    #[default]
    Uniform,
    /// From the cells' extents, one log-ratio per knot surface (graded grids reproduced).
    Graded,
}

/// Parameters of the knot intervals.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct KnotParams {
    pub intervals: KnotIntervals,
    /// Largest ratio of neighbouring intervals (≥ 1); larger measured ratios are clamped.
    pub max_ratio: f64,
}

impl Default for KnotParams {
    fn default() -> Self {
        KnotParams {
            intervals: KnotIntervals::Uniform,
            max_ratio: 16.0,
        }
    }
}

impl KnotParams {
    /// Uniform knots.
    pub fn uniform() -> Self {
        KnotParams {
            intervals: KnotIntervals::Uniform,
            ..Default::default()
        }
    }

    pub fn check(&self) -> Result<(), ParamError> {
        above("--knot-max-ratio", self.max_ratio, 1.0 - f64::EPSILON, 1e6)
    }
}

/// The extraction weights `[α, β]` of each element direction (z unused in 2D).
pub type KnotWeights = [[f64; 2]; 3];

/// Figures of the knot surfaces (for reports and tests).
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
pub struct KnotSurfaceInfo {
    /// Knot surfaces with at least one interior facet.
    pub surfaces: usize,
    /// Of those, surfaces whose ratio is not 1.
    pub graded: usize,
    /// Surfaces closing on themselves with opposite orientation (given uniform knots).
    pub non_orientable: usize,
    /// Surfaces whose measured ratio was clamped to `max_ratio`.
    pub clamped: usize,
    /// Largest |ln ratio| assigned.
    pub max_abs_log_ratio: f64,
}

/// Union-find with the orientation of each facet relative to its parent.
struct SignedUnionFind {
    parent: Vec<u32>,
    /// `ρ(x) = sign[x] · ρ(parent[x])`, sign ±1 stored as `true` for −1.
    flip: Vec<bool>,
    /// Root: a cycle with an odd number of flips was found.
    conflict: Vec<bool>,
}

impl SignedUnionFind {
    fn new(n: usize) -> Self {
        SignedUnionFind {
            parent: (0..n as u32).collect(),
            flip: vec![false; n],
            conflict: vec![false; n],
        }
    }

    /// Root of `x` and whether `ρ(x) = −ρ(root)` (path compression).
    fn find(&mut self, x: u32) -> (u32, bool) {
        let mut path = Vec::new();
        let mut r = x;
        while self.parent[r as usize] != r {
            path.push(r);
            r = self.parent[r as usize];
        }
        // From the top of the path down: flip relative to the root.
        let mut acc = false;
        for &p in path.iter().rev() {
            acc ^= self.flip[p as usize];
            self.flip[p as usize] = acc;
            self.parent[p as usize] = r;
        }
        (
            r,
            if path.is_empty() {
                false
            } else {
                self.flip[x as usize]
            },
        )
    }

    /// Record `ρ(a) = ±ρ(b)` (`opposite`: minus).
    fn union(&mut self, a: u32, b: u32, opposite: bool) {
        let (ra, fa) = self.find(a);
        let (rb, fb) = self.find(b);
        if ra == rb {
            if fa ^ fb != opposite {
                self.conflict[ra as usize] = true;
            }
            return;
        }
        self.parent[rb as usize] = ra;
        self.flip[rb as usize] = fa ^ fb ^ opposite;
        if self.conflict[rb as usize] {
            self.conflict[ra as usize] = true;
        }
    }
}

fn centre(mesh: &LinearMesh, vs: &[u32]) -> [f64; 3] {
    let mut c = [0.0; 3];
    for &v in vs {
        let p = mesh.coords[v as usize];
        for i in 0..3 {
            c[i] += p[i] / vs.len() as f64;
        }
    }
    c
}

/// Extent of element `e` in its local direction `k`: the distance between the centres of its
/// two faces normal to k.
fn extent(mesh: &LinearMesh, topo: &Topology, e: usize, k: usize) -> f64 {
    let a = centre(
        mesh,
        topo.facet_vertices(topo.element_facet(e, 2 * k) as usize),
    );
    let b = centre(
        mesh,
        topo.facet_vertices(topo.element_facet(e, 2 * k + 1) as usize),
    );
    ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt()
}

/// Length (2D) or area (3D, from the diagonals) of a facet.
fn facet_size(mesh: &LinearMesh, vs: &[u32]) -> f64 {
    let p = |i: usize| mesh.coords[vs[i] as usize];
    let d = |a: [f64; 3], b: [f64; 3]| [b[0] - a[0], b[1] - a[1], b[2] - a[2]];
    if vs.len() == 2 {
        let v = d(p(0), p(1));
        (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt()
    } else {
        let (u, v) = (d(p(0), p(2)), d(p(1), p(3)));
        let c = [
            u[1] * v[2] - u[2] * v[1],
            u[2] * v[0] - u[0] * v[2],
            u[0] * v[1] - u[1] * v[0],
        ];
        0.5 * (c[0] * c[0] + c[1] * c[1] + c[2] * c[2]).sqrt()
    }
}

/// −1 (`true`) when `e` is the second element of facet `f`, so that `ln(h_other / h_e)`
/// is `±ρ(f)` with `ρ(f) = ln(h_second / h_first)`.
fn second(topo: &Topology, f: u32, e: usize) -> bool {
    topo.facet_elements[f as usize][0] != e as u32
}

/// The extraction weights of every element for `params` (`None`: uniform knots), with the
/// figures of the knot surfaces. Knot surfaces are continued across the elements that are
/// spline elements by topology (`spline[e]`); elsewhere the continuation is not defined.
pub fn knot_weights(
    mesh: &LinearMesh,
    topo: &Topology,
    spline: &[bool],
    params: &KnotParams,
) -> (Option<Vec<KnotWeights>>, KnotSurfaceInfo) {
    if params.intervals == KnotIntervals::Uniform {
        return (None, KnotSurfaceInfo::default());
    }
    let dim = topo.dim;
    let nf = topo.n_facets();
    let ne = topo.n_elements;
    let sides = topo.sides();

    // 1. Knot surfaces: facet pairs continued across each spline element's neighbours.
    let mut uf = SignedUnionFind::new(nf);
    for e in 0..ne {
        if !spline[e] {
            continue;
        }
        for side in 0..sides {
            let f = topo.element_facet(e, side);
            for other in 0..sides {
                if other / 2 == side / 2 {
                    continue;
                }
                let n = topo.neighbor(e, other);
                if n == NONE || n as usize == e {
                    continue;
                }
                let g = topo.element_facet(e, other);
                let fv = topo.facet_vertices(f as usize);
                let common: Vec<u32> = topo
                    .facet_vertices(g as usize)
                    .iter()
                    .copied()
                    .filter(|v| fv.contains(v))
                    .collect();
                if common.len() != dim - 1 {
                    continue;
                }
                let n = n as usize;
                let mut found = None;
                for s2 in 0..sides {
                    let f2 = topo.element_facet(n, s2);
                    if f2 == g {
                        continue;
                    }
                    let v2 = topo.facet_vertices(f2 as usize);
                    if common.iter().all(|v| v2.contains(v)) {
                        if found.is_some() {
                            found = None;
                            break;
                        }
                        found = Some(f2);
                    }
                }
                if let Some(f2) = found {
                    uf.union(f, f2, second(topo, f, e) ^ second(topo, f2, n));
                }
            }
        }
    }

    // 2. Measured log-ratio of every interior facet, summed per surface with weight 1 / the
    //    facet's size: a ratio that misfits a thin cell distorts it relative to its thickness,
    //    so the small facets of a boundary layer decide where a surface crosses it.
    let measured: Vec<Option<(f64, f64)>> = (0..nf)
        .into_par_iter()
        .map(|f| {
            let [a, b] = topo.facet_elements[f];
            if a == NONE || b == NONE || a == b {
                return None;
            }
            let [sa, sb] = topo.facet_sides[f];
            let ea = extent(mesh, topo, a as usize, sa as usize / 2);
            let eb = extent(mesh, topo, b as usize, sb as usize / 2);
            let r = (eb / ea).ln();
            let w = 1.0 / facet_size(mesh, topo.facet_vertices(f));
            (r.is_finite() && w.is_finite()).then_some((r, w))
        })
        .collect();
    let mut sum = vec![0.0f64; nf];
    let mut weight = vec![0.0f64; nf];
    let mut sign = vec![false; nf];
    let mut root = vec![0u32; nf];
    for f in 0..nf {
        let (r, s) = uf.find(f as u32);
        root[f] = r;
        sign[f] = s;
        if let Some((m, w)) = measured[f] {
            sum[r as usize] += w * if s { -m } else { m };
            weight[r as usize] += w;
        }
    }
    let cap = params.max_ratio.ln();
    let mut info = KnotSurfaceInfo::default();
    let mut rho_root = vec![0.0f64; nf];
    for r in 0..nf {
        if weight[r] == 0.0 || root[r] as usize != r {
            continue;
        }
        info.surfaces += 1;
        if uf.conflict[r] {
            info.non_orientable += 1;
            continue;
        }
        let mut rho = sum[r] / weight[r];
        if rho.abs() > cap {
            info.clamped += 1;
            rho = rho.clamp(-cap, cap);
        }
        if rho != 0.0 {
            info.graded += 1;
        }
        info.max_abs_log_ratio = info.max_abs_log_ratio.max(rho.abs());
        rho_root[r] = rho;
    }
    let rho = |f: u32| {
        let v = rho_root[root[f as usize] as usize];
        if sign[f as usize] { -v } else { v }
    };

    // 3. Weights: α = 1/(1 + h₋₁/h₀), β = 1/(1 + h₀/h₁).
    let logistic = |x: f64| 1.0 / (1.0 + (-x).exp());
    let weights = (0..ne)
        .into_par_iter()
        .map(|e| {
            let mut w = [[0.5; 2]; 3];
            for (k, wk) in w.iter_mut().enumerate().take(dim) {
                for (s, ws) in wk.iter_mut().enumerate() {
                    let f = topo.element_facet(e, 2 * k + s);
                    if topo.neighbor(e, 2 * k + s) == NONE {
                        continue;
                    }
                    // ln(h_other / h_e) across this facet.
                    let out = if second(topo, f, e) { -rho(f) } else { rho(f) };
                    // Left (s = 0): α = 1/(1 + h₋₁/h₀); right: β = 1/(1 + h₀/h₁).
                    *ws = if s == 0 {
                        logistic(-out)
                    } else {
                        logistic(out)
                    };
                }
            }
            w
        })
        .collect();
    (Some(weights), info)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn signed_union_find_detects_odd_cycles() {
        let mut u = SignedUnionFind::new(4);
        u.union(0, 1, true);
        u.union(1, 2, true);
        let (r0, f0) = u.find(0);
        let (r2, f2) = u.find(2);
        assert_eq!(r0, r2);
        assert_eq!(f0, f2);
        u.union(0, 2, false);
        let r = u.find(0).0 as usize;
        assert!(!u.conflict[r]);
        u.union(0, 2, true);
        let r = u.find(0).0 as usize;
        assert!(u.conflict[r]);
    }

    #[test]
    fn params_check() {
        assert!(KnotParams::default().check().is_ok());
        let p = KnotParams {
            max_ratio: 0.5,
            ..Default::default()
        };
        assert_eq!(p.check().unwrap_err().option, "--knot-max-ratio");
    }
}
