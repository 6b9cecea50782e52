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
//! **Splitting.** One ratio per surface cannot fit a surface along which the cells' ratio
//! changes a lot (a C-grid's first layers: the trailing edge's growth is not the leading
//! edge's). With a finite [`KnotParams::max_spread`], neighbouring element pairs are taken in
//! order of increasing disagreement of the ratios they tie together, and a pair is refused when
//! tying would make the spread (max − min) of the measured log-ratios of a surface exceed
//! `max_spread`, Kruskal-like. Both elements of a refused pair become Q2 elements
//! ([`super::Q2Reason::KnotSplit`]): ratios are tied only across a face with a spline element on
//! at least one side, so the surface is cut there, and the Q2 elements' constraints keep the
//! map C⁰ across the cut (C¹ is kept where the mesh is regular enough for one ratio). A
//! surface whose ratio exceeds [`KnotParams::max_ratio`] is clamped to it, and one whose ratio
//! exceeds its cube (a boundary layer ending in one far-field cell 10⁶ times as high as its
//! last layer) is split the same way: every element along it becomes Q2, and the surfaces are
//! rebuilt once without their ties.
//!
//! Invariants: the weights lie in `[1/(1+r), r/(1+r)]` with `r` = [`KnotParams::max_ratio`];
//! a tensor-product grid (any spacing per direction) under an affine map gets exactly its
//! spacing ratios, so the initial spline map (control points at cell centres, Greville
//! abscissae) equals the straight map; the result depends only on topology and coordinates.
//! Surfaces closing on themselves with opposite orientation (non-orientable continuation) get
//! uniform knots.
//!
//! **Auto** (the default) is decided by `curve` (`pipeline::spline::curve_spline`), in one
//! spline pass where it can. Graded knots straight away where at least [`AUTO_GRADED_SHARE`]
//! of the interior facets lie on consistently graded surfaces of the unsplit knot surfaces
//! ([`KnotSurfaceInfo::graded_share`]: weighted mean |ln ratio| ≥ 0.1 with ≥ 90 % of the
//! surface's measured ratios on its side; a boundary-layer grid). Otherwise uniform knots,
//! and graded ones (a second pass) where the certified blend holds back more than a tenth of
//! the elements with uniform knots and at most half as many with graded ones (not tried where
//! no facet's |ln ratio| reaches [`AUTO_MIN_LOG_RATIO`]). The share alone does not
//! separate every mesh where graded knots win from unstructured ones (sphere_r6 0.043
//! against systems_of_equations_ex9 0.051; `git show 81dad3f:BENCHMARKS.md`, "Graded knot
//! intervals"), hence the outcome rule below the threshold. Without a fit (`info`, `plot`),
//! auto is uniform. Under mpirun the ranks decide alike on the whole mesh's survey and
//! counts, and use the serial weights (`distributed::knots`).
//!
//! **Glued periodic seams** ([`survey_glued`]): the knot surfaces are continued on the glued
//! topology, across the seams, and every element is measured on its own vertices of the
//! unglued input; a translation keeps the cells' extents, so a surface crossing a seam gets
//! one ratio from the cells of both sides and the seam stays C¹ with graded knots.

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
    Uniform,
    /// From the cells' extents, one log-ratio per knot surface (graded grids reproduced).
    Graded,
    /// The default. `curve` decides (`pipeline::spline::curve_spline`): graded where
    /// [`KnotSurfaceInfo::graded_share`] reaches [`AUTO_GRADED_SHARE`]; else uniform, unless
    /// the certified blend then holds back more than a tenth of the elements and at most half
    /// as many with graded knots, graded then. Where nothing is fitted (`info`, `plot`), uniform.
    #[default]
    Auto,
}

/// Parameters of the knot intervals.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct KnotParams {
    pub intervals: KnotIntervals,
    /// Largest ratio of neighbouring intervals (≥ 1); a knot surface whose ratio is larger is
    /// clamped to it, and split (its elements Q2) where the ratio exceeds its cube.
    pub max_ratio: f64,
    /// Largest spread (max − min) of the measured log-ratios within one knot surface before
    /// it is split (`f64::INFINITY`: never split).
    pub max_spread: f64,
}

impl Default for KnotParams {
    fn default() -> Self {
        KnotParams {
            intervals: KnotIntervals::Auto,
            max_ratio: 16.0,
            max_spread: DEFAULT_MAX_SPREAD,
        }
    }
}

/// Default [`KnotParams::max_spread`].
pub const DEFAULT_MAX_SPREAD: f64 = 0.3;

impl KnotParams {
    /// Uniform knots.
    pub fn uniform() -> Self {
        KnotParams {
            intervals: KnotIntervals::Uniform,
            ..Default::default()
        }
    }

    pub fn check(&self) -> Result<(), ParamError> {
        above("--knot-max-ratio", self.max_ratio, 1.0 - f64::EPSILON, 1e6)?;
        if self.max_spread.is_nan() || self.max_spread < 0.0 {
            return Err(ParamError::new(
                "--knot-max-spread",
                crate::params::num(self.max_spread),
                "must be ≥ 0 (inf: never split)",
            ));
        }
        Ok(())
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
    /// Surfaces whose measured ratio exceeded `max_ratio` (clamped, or split with their
    /// elements Q2 beyond its cube).
    pub clamped: usize,
    /// Largest |ln ratio| assigned.
    pub max_abs_log_ratio: f64,
    /// Elements made Q2 where knot surfaces were split ([`KnotParams::max_spread`]).
    pub split_elements: usize,
    /// Largest spread (max − min) of the measured log-ratios within one surface, after
    /// splitting.
    pub max_spread: f64,
    /// Share of the interior facets on consistently graded surfaces of the unsplit knot
    /// surfaces (`graded_share`): `--knot-intervals auto` takes graded knots without trying
    /// uniform ones from [`AUTO_GRADED_SHARE`] on.
    pub graded_share: f64,
}

/// With `--knot-intervals auto`: from this [`KnotSurfaceInfo::graded_share`] on, the mesh is
/// a boundary-layer grid that uniform knots cannot follow, and graded knots are taken without
/// a uniform pass. Real meshes: 0.37 (turbine) to 0.74 (NACA4412) where graded knots hold back
/// fewer elements (or, on spheremesh01 and 70degCone_3D, as many); 0.25 (cylinder-hex) and
/// below where uniform knots are kept, 0.14 and below on the rest; the generated O-grids of the
/// fidelity tests 0.06 to 0.12 (`git show 81dad3f:BENCHMARKS.md`, "Graded knot intervals").
pub const AUTO_GRADED_SHARE: f64 = 0.3;

/// With `--knot-intervals auto`: where no interior facet's cells differ this much in extent
/// across it ([`KnotSurvey::max_abs_log_ratio`] below it), no knot surface is graded by more
/// either, every extraction weight lies within 0.5 ± 0.025, and the graded pass is not run
/// after the uniform one: graded knots that close to uniform do not hold back half as many
/// elements (sfepy/hsphere8, largest |ln ratio| < 0.05: 20 % held back against uniform
/// knots' 24 %). Every mesh where graded knots were kept after a uniform pass has facets of
/// |ln ratio| ≥ 0.2 (`git show 81dad3f:BENCHMARKS.md`, "Automatic choice").
pub const AUTO_MIN_LOG_RATIO: f64 = 0.1;

/// Smallest |weighted mean log-ratio| of a consistently graded surface ([`graded_share`]).
const CONSISTENT_LOG_RATIO: f64 = 0.1;
/// Smallest share of a consistently graded surface's measured ratios on its mean's side.
const CONSISTENT_SIGN_SHARE: f64 = 0.9;

/// The share of the interior facets (those with a measured ratio) that lie on a knot surface
/// of `uf` with a consistent grading: the 1 / facet-size weighted mean of its measured
/// log-ratios is at least [`CONSISTENT_LOG_RATIO`] in size and at least
/// [`CONSISTENT_SIGN_SHARE`] of its facets' ratios have the mean's sign. A boundary layer's
/// surfaces crossing the layer are such surfaces; on an unstructured mesh a surface wanders
/// through cells of every ratio and averages out.
fn graded_share(uf: &mut SignedUnionFind, measured: &[Option<(f64, f64)>]) -> f64 {
    let nf = measured.len();
    // Per root: weighted sum, weight, facets, facets with a positive ratio (root's sign).
    let mut acc = vec![(0.0f64, 0.0f64, 0usize, 0usize); nf];
    for (f, m) in measured.iter().enumerate() {
        let Some((m, w)) = *m else { continue };
        let (r, s) = uf.find(f as u32);
        let m = if s { -m } else { m };
        let a = &mut acc[r as usize];
        a.0 += w * m;
        a.1 += w;
        a.2 += 1;
        a.3 += usize::from(m > 0.0);
    }
    let (mut consistent, mut total) = (0usize, 0usize);
    for (r, &(sum, weight, n, positive)) in acc.iter().enumerate() {
        total += n;
        if n == 0 || uf.conflict[r] {
            continue;
        }
        let mean = sum / weight;
        let side = if mean > 0.0 { positive } else { n - positive };
        if mean.abs() >= CONSISTENT_LOG_RATIO && side as f64 >= CONSISTENT_SIGN_SHARE * n as f64 {
            consistent += n;
        }
    }
    if total == 0 {
        0.0
    } else {
        consistent as f64 / total as f64
    }
}

/// The knot intervals of a mesh: what [`knot_weights`] returns.
#[derive(Clone, Debug, Default)]
pub struct Knots {
    /// Extraction weights per element (`None`: uniform knots).
    pub weights: Option<Vec<KnotWeights>>,
    /// Elements to make Q2 ([`super::Q2Reason::KnotSplit`]; empty: none).
    pub split: Vec<bool>,
    pub info: KnotSurfaceInfo,
}

/// Union-find with the orientation of each facet relative to its parent.
struct SignedUnionFind {
    /// Per facet: its parent, with `ρ(x) = sign · ρ(parent)` in the top bit (set: −1), so that
    /// one load gives both (the survey runs it over every tie of a mesh, and the facets'
    /// entries are visited in no cache-friendly order).
    link: Vec<u32>,
    /// Root: a cycle with an odd number of flips was found.
    conflict: Vec<bool>,
    /// Root: smallest and largest value of the set's members, in the root's orientation
    /// (empty: `lo > hi`).
    range: Vec<[f64; 2]>,
}

/// The flip bit of [`SignedUnionFind::link`].
const FLIP: u32 = 1 << 31;

impl SignedUnionFind {
    fn new(n: usize) -> Self {
        assert!(n <= FLIP as usize, "at most 2^31 facets");
        SignedUnionFind {
            link: (0..n as u32).collect(),
            conflict: vec![false; n],
            range: vec![[f64::INFINITY, f64::NEG_INFINITY]; n],
        }
    }

    /// Singletons with values (`None`: no value).
    fn with_values(values: impl Iterator<Item = Option<f64>>) -> Self {
        let values: Vec<Option<f64>> = values.collect();
        let mut u = Self::new(values.len());
        for (i, v) in values.into_iter().enumerate() {
            if let Some(v) = v {
                u.range[i] = [v, v];
            }
        }
        u
    }

    /// Root `r`'s smallest and largest value.
    fn lo_hi(&self, r: u32) -> (f64, f64) {
        let [lo, hi] = self.range[r as usize];
        (lo, hi)
    }

    /// The range of the set `a`'s and `b`'s would form under `ρ(a) = ±ρ(b)`, in `a`'s root's
    /// orientation (empty: `lo > hi`).
    fn merged_range(&mut self, a: u32, b: u32, opposite: bool) -> (f64, f64) {
        let (ra, fa) = self.find(a);
        let (rb, fb) = self.find(b);
        self.merged_roots(ra, rb, fa ^ fb ^ opposite)
    }

    /// [`SignedUnionFind::merged_range`] of roots `ra` and `rb` under `ρ(ra) = ±ρ(rb)`
    /// (`flip`: minus).
    fn merged_roots(&self, ra: u32, rb: u32, flip: bool) -> (f64, f64) {
        let (lo, hi) = self.lo_hi(ra);
        if ra == rb {
            return (lo, hi);
        }
        let (blo, bhi) = self.lo_hi(rb);
        let (blo, bhi) = if flip { (-bhi, -blo) } else { (blo, bhi) };
        (lo.min(blo), hi.max(bhi))
    }

    /// Root of `x` and whether `ρ(x) = −ρ(root)` (path compression, without allocating: it
    /// runs for every tie of a mesh).
    fn find(&mut self, x: u32) -> (u32, bool) {
        let (mut r, mut parity) = (x, false);
        loop {
            let l = self.link[r as usize];
            if l & !FLIP == r {
                break;
            }
            parity ^= l & FLIP != 0;
            r = l & !FLIP;
        }
        // Point every node on the path at the root, with its flip relative to the root.
        let (mut y, mut py) = (x, parity);
        while y != r {
            let l = self.link[y as usize];
            self.link[y as usize] = r | if py { FLIP } else { 0 };
            (y, py) = (l & !FLIP, py ^ (l & FLIP != 0));
        }
        (r, parity)
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
        let flip = fa ^ fb ^ opposite;
        let (lo, hi) = self.merged_roots(ra, rb, flip);
        self.link[rb as usize] = ra | if flip { FLIP } else { 0 };
        self.range[ra as usize] = [lo, hi];
        if self.conflict[rb as usize] {
            self.conflict[ra as usize] = true;
        }
    }
}

/// Where element `e` has its vertex `v` (of the topology's numbering): the mesh's own
/// coordinates, or, on a glued mesh, the position of that corner of the element in the
/// unglued input, so that every element is measured on its own vertices.
#[derive(Clone, Copy)]
struct Corners<'a> {
    mesh: &'a LinearMesh,
    unglued: Option<&'a LinearMesh>,
    /// A sub-mesh of a larger mesh: the larger mesh's index of each element, whose order
    /// decides a facet's first element and its vertices' order as on the larger mesh (`None`:
    /// the mesh's own).
    global: Option<&'a [u64]>,
}

impl Corners<'_> {
    fn at(&self, e: usize, v: u32) -> [f64; 3] {
        let Some(input) = self.unglued else {
            return self.mesh.coords[v as usize];
        };
        let npe = self.mesh.nodes_per_element();
        let row = &self.mesh.elements[e * npe..(e + 1) * npe];
        let i = row
            .iter()
            .position(|&w| w == v)
            .expect("a facet vertex is a vertex of its element");
        input.coords[input.elements[e * npe + i] as usize]
    }

    fn centre(&self, e: usize, vs: &[u32]) -> [f64; 3] {
        let mut c = [0.0; 3];
        for &v in vs {
            let p = self.at(e, v);
            for i in 0..3 {
                c[i] += p[i] / vs.len() as f64;
            }
        }
        c
    }

    /// The elements of facet `f`, first the one the topology of the whole mesh puts first
    /// (with `global`, the lower global index), and their local sides.
    fn elements(&self, topo: &Topology, f: usize) -> ([u32; 2], [u8; 2]) {
        match self.global {
            Some(g) => elements_in_global_order(topo, f, g),
            None => (topo.facet_elements[f], topo.facet_sides[f]),
        }
    }

    /// The vertices of facet `f` in the order the whole mesh's topology lists them (its first
    /// element's side, [`Topology::faces`]; a centre's sum depends on the order).
    fn facet<'t>(&self, topo: &'t Topology, f: usize, buf: &'t mut [u32; 4]) -> &'t [u32] {
        if self.global.is_none() || topo.dim == 2 {
            return topo.facet_vertices(f);
        }
        let ([e, _], [side, _]) = self.elements(topo, f);
        let npe = self.mesh.nodes_per_element();
        let row = &self.mesh.elements[e as usize * npe..(e as usize + 1) * npe];
        *buf = crate::math::reference::HEX_SIDES[side as usize].map(|c| row[c]);
        &buf[..]
    }

    /// Extent of element `e` in its local direction `k`: the distance between the centres of
    /// its two faces normal to k.
    fn extent(&self, topo: &Topology, e: usize, k: usize) -> f64 {
        let (mut b0, mut b1) = ([0u32; 4], [0u32; 4]);
        let face0 = self.facet(topo, topo.element_facet(e, 2 * k) as usize, &mut b0);
        let face1 = self.facet(topo, topo.element_facet(e, 2 * k + 1) as usize, &mut b1);
        let (a, b) = (self.centre(e, face0), self.centre(e, face1));
        ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt()
    }

    /// Length (2D) or area (3D, from the diagonals) of facet `vs` of element `e`.
    fn facet_size(&self, e: usize, vs: &[u32]) -> f64 {
        let p = |i: usize| self.at(e, vs[i]);
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
}

/// −1 (`true`) when `e` is the second element of facet `f`, so that `ln(h_other / h_e)`
/// is `±ρ(f)` with `ρ(f) = ln(h_second / h_first)`.
fn second(topo: &Topology, f: u32, e: usize) -> bool {
    topo.facet_elements[f as usize][0] != e as u32
}

/// The elements of facet `f` of a sub-mesh's topology and their sides, first the one with
/// the lower index `global[e]` in the larger mesh: the order the larger mesh's topology gives
/// them.
pub(crate) fn elements_in_global_order(
    topo: &Topology,
    f: usize,
    global: &[u64],
) -> ([u32; 2], [u8; 2]) {
    let ([a, b], [sa, sb]) = (topo.facet_elements[f], topo.facet_sides[f]);
    if b != NONE && global[b as usize] < global[a as usize] {
        ([b, a], [sb, sa])
    } else {
        ([a, b], [sa, sb])
    }
}

/// One tie `ρ(f) = ±ρ(f2)` made by continuing facet `f` of `element` across its face to
/// `neighbour` (`opposite`: minus). 16 bytes: a mesh has about 24 per hex.
#[derive(Clone, Copy)]
pub(crate) struct Tie {
    pub(crate) element: u32,
    pub(crate) neighbour: u32,
    pub(crate) f: u32,
    /// `f2`, with `opposite` in the top bit.
    f2_opposite: u32,
}

impl Tie {
    pub(crate) fn new(element: u32, neighbour: u32, f: u32, f2: u32, opposite: bool) -> Tie {
        debug_assert!(f2 < 1 << 31, "facet numbers below 2^31");
        Tie {
            element,
            neighbour,
            f,
            f2_opposite: f2 | (u32::from(opposite) << 31),
        }
    }
    pub(crate) fn f2(&self) -> u32 {
        self.f2_opposite & !(1 << 31)
    }
    pub(crate) fn opposite(&self) -> bool {
        self.f2_opposite >> 31 == 1
    }
}

/// Every tie of the knot surfaces continued across the spline elements (`spline[e]`), each
/// facet's sign ([`second`]) as `corners` orders its elements.
fn ties(topo: &Topology, spline: &[bool], corners: Corners) -> Vec<Tie> {
    let second = |f: u32, e: usize| corners.elements(topo, f as usize).0[0] != e as u32;
    let dim = topo.dim;
    let sides = topo.sides();
    let ties_of = |e: usize, out: &mut Vec<Tie>| {
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
                // The vertices f and g share (an edge in 3D, a vertex in 2D).
                let fv = topo.facet_vertices(f as usize);
                let (mut shared, mut n_shared) = ([0u32; 2], 0);
                for &v in topo.facet_vertices(g as usize) {
                    if fv.contains(&v) {
                        if n_shared < 2 {
                            shared[n_shared] = v;
                        }
                        n_shared += 1;
                    }
                }
                if n_shared != dim - 1 {
                    continue;
                }
                let common = &shared[..n_shared];
                let mut found = None;
                for s2 in 0..sides {
                    let f2 = topo.element_facet(n as usize, s2);
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
                    let opposite = second(f, e) ^ second(f2, n as usize);
                    out.push(Tie::new(e as u32, n, f, f2, opposite));
                }
            }
        }
    };
    // Runs of elements give their ties in parallel, and the runs' lists are joined by the
    // workers too (rayon's collect of a flat map appends them on the calling thread).
    let ne = topo.n_elements;
    let parts: Vec<Vec<Tie>> = (0..ne.div_ceil(TIE_RUN))
        .into_par_iter()
        .map(|k| {
            let mut out = Vec::new();
            for e in (k * TIE_RUN..ne.min((k + 1) * TIE_RUN)).filter(|&e| spline[e]) {
                ties_of(e, &mut out);
            }
            out
        })
        .collect();
    concat(&parts)
}

/// Elements per run of [`ties`].
const TIE_RUN: usize = 2048;

/// `parts` one after the other, written by the workers: each slot's part is found by a
/// binary search of the parts' starts (rayon hands each worker a contiguous range, so the
/// parts are read in order).
pub(crate) fn concat<T: Copy + Send + Sync>(parts: &[Vec<T>]) -> Vec<T> {
    let mut starts = Vec::with_capacity(parts.len() + 1);
    starts.push(0usize);
    for p in parts {
        starts.push(starts[starts.len() - 1] + p.len());
    }
    let total = starts[parts.len()];
    (0..total)
        .into_par_iter()
        .with_min_len(1 << 12)
        .map(|i| {
            let k = starts.partition_point(|&s| s <= i) - 1;
            parts[k][i - starts[k]]
        })
        .collect()
}

/// The knot surfaces of `ties` (facets in one set share a ratio up to sign), with the
/// measured log-ratios as the sets' values.
fn surfaces<'a>(
    nf: usize,
    ties: impl IntoIterator<Item = &'a Tie>,
    measured: &[Option<(f64, f64)>],
) -> SignedUnionFind {
    let mut uf = SignedUnionFind::with_values((0..nf).map(|f| measured[f].map(|(m, _)| m)));
    for t in ties {
        uf.union(t.f, t.f2(), t.opposite());
    }
    uf
}

/// The elements to make Q2 so that no knot surface's measured log-ratios spread more than
/// `max_spread` (module docs: element pairs in order of increasing disagreement; a pair whose
/// ties would spread a surface too far is refused and both its elements marked).
fn split_elements(
    ne: usize,
    nf: usize,
    ties: &[Tie],
    measured: &[Option<(f64, f64)>],
    max_spread: f64,
) -> Vec<bool> {
    let mut split = vec![false; ne];
    if !max_spread.is_finite() {
        return split;
    }
    let value = |f: u32| measured[f as usize].map(|(m, _)| m);
    // Ties grouped by unordered element pair (then by index), with the pair's largest
    // disagreement; the order holds tie indices only (4 B a tie, not the keys).
    let pair = |i: u32| {
        let t = &ties[i as usize];
        let (a, b) = (t.element.min(t.neighbour), t.element.max(t.neighbour));
        ((a as u64) << 32) | b as u64
    };
    let mut order: Vec<u32> = (0..ties.len() as u32).collect();
    order.par_sort_unstable_by_key(|&i| (pair(i), i));
    let mut pairs: Vec<(f64, usize, usize)> = Vec::new();
    let mut i = 0;
    while i < order.len() {
        let mut j = i;
        let mut worst = 0.0f64;
        while j < order.len() && pair(order[j]) == pair(order[i]) {
            let t = &ties[order[j] as usize];
            if let (Some(a), Some(b)) = (value(t.f), value(t.f2())) {
                let b = if t.opposite() { -b } else { b };
                worst = worst.max((a - b).abs());
            }
            j += 1;
        }
        pairs.push((worst, i, j));
        i = j;
    }
    pairs.par_sort_by(|a, b| a.0.total_cmp(&b.0));
    let mut uf = SignedUnionFind::with_values((0..nf).map(|f| value(f as u32)));
    for &(_, i, j) in &pairs {
        let group = &order[i..j];
        let fits = group.iter().all(|&k| {
            let t = &ties[k as usize];
            let (lo, hi) = uf.merged_range(t.f, t.f2(), t.opposite());
            lo > hi || hi - lo <= max_spread
        });
        if fits {
            for &k in group {
                let t = &ties[k as usize];
                uf.union(t.f, t.f2(), t.opposite());
            }
        } else {
            let t = &ties[group[0] as usize];
            split[t.element as usize] = true;
            split[t.neighbour as usize] = true;
        }
    }
    split
}

/// What graded knot intervals are built from: every interior facet's measured log-ratio and
/// the ties of the knot surfaces ([`survey`]), with the share of the facets on consistently
/// graded surfaces (`--knot-intervals auto` decides on it before any fit).
pub struct KnotSurvey {
    /// Per facet: the measured log-ratio and its weight (`None`: not an interior facet).
    pub(crate) measured: Vec<Option<(f64, f64)>>,
    pub(crate) ties: Vec<Tie>,
    /// [`KnotSurfaceInfo::graded_share`].
    pub graded_share: f64,
    /// Largest |measured log-ratio| of an interior facet (0 without one): below
    /// [`AUTO_MIN_LOG_RATIO`] graded knots are all but uniform.
    pub max_abs_log_ratio: f64,
}

/// The measured ratios, ties and graded share of the knot surfaces continued across the
/// elements that are spline elements by topology (`spline[e]`).
pub fn survey(mesh: &LinearMesh, topo: &Topology, spline: &[bool]) -> KnotSurvey {
    survey_with(
        Corners {
            mesh,
            unglued: None,
            global: None,
        },
        topo,
        spline,
    )
}

/// [`survey`] of a glued mesh (`glued`, `topo`: translation-periodic sides identified,
/// [`super::seam::glue`]) whose elements are measured on their own vertices in `input` (same
/// elements, same corner order): a translation keeps lengths, so a knot surface crossing a
/// seam measures the same cells on both sides and gets one ratio.
pub fn survey_glued(
    input: &LinearMesh,
    glued: &LinearMesh,
    topo: &Topology,
    spline: &[bool],
) -> KnotSurvey {
    survey_with(
        Corners {
            mesh: glued,
            unglued: Some(input),
            global: None,
        },
        topo,
        spline,
    )
}

fn survey_with(corners: Corners, topo: &Topology, spline: &[bool]) -> KnotSurvey {
    let (measured, ties) = survey_parts_with(corners, topo, spline);
    KnotSurvey::from_parts(measured, ties)
}

/// What [`survey`] is made of, on a sub-mesh of a larger mesh whose elements' indices there
/// are `global` (each element's nodes in the larger mesh's order): every facet's measured
/// log-ratio with its weight (`None` where it is not interior here) and the ties of the knot
/// surfaces continued across the elements with `spline[e]`, each facet oriented and its
/// vertices summed as the larger mesh's topology does (its first element the lower global
/// index), so a facet whose elements are both here is measured bit for bit as [`survey`]
/// measures it on the larger mesh. [`KnotSurvey::from_parts`] joins the parts of the whole
/// mesh; a rank of a distributed job surveys its share with it (`distributed::knots`).
#[allow(clippy::type_complexity)]
pub(crate) fn survey_parts(
    mesh: &LinearMesh,
    topo: &Topology,
    spline: &[bool],
    global: &[u64],
) -> (Vec<Option<(f64, f64)>>, Vec<Tie>) {
    let corners = Corners {
        mesh,
        unglued: None,
        global: Some(global),
    };
    survey_parts_with(corners, topo, spline)
}

/// [`survey_parts`] of a sub-mesh glued along its translation seams (`glued`, `topo`:
/// [`super::seam::glue_share`]) whose elements are measured on their own vertices in `input`,
/// as [`survey_glued`] measures the whole glued mesh.
#[allow(clippy::type_complexity)]
pub(crate) fn survey_parts_glued(
    input: &LinearMesh,
    glued: &LinearMesh,
    topo: &Topology,
    spline: &[bool],
    global: &[u64],
) -> (Vec<Option<(f64, f64)>>, Vec<Tie>) {
    let corners = Corners {
        mesh: glued,
        unglued: Some(input),
        global: Some(global),
    };
    survey_parts_with(corners, topo, spline)
}

#[allow(clippy::type_complexity)]
fn survey_parts_with(
    corners: Corners,
    topo: &Topology,
    spline: &[bool],
) -> (Vec<Option<(f64, f64)>>, Vec<Tie>) {
    let nf = topo.n_facets();
    // Measured log-ratio of every interior facet, with weight 1 / the facet's size: a ratio
    // that misfits a thin cell distorts it relative to its thickness, so the small facets of
    // a boundary layer decide where a surface crosses it.
    let measured: Vec<Option<(f64, f64)>> = (0..nf)
        .into_par_iter()
        .map(|f| {
            let ([a, b], [sa, sb]) = corners.elements(topo, f);
            if a == NONE || b == NONE || a == b {
                return None;
            }
            let ea = corners.extent(topo, a as usize, sa as usize / 2);
            let eb = corners.extent(topo, b as usize, sb as usize / 2);
            let r = (eb / ea).ln();
            let mut buf = [0u32; 4];
            let w = 1.0 / corners.facet_size(a as usize, corners.facet(topo, f, &mut buf));
            (r.is_finite() && w.is_finite()).then_some((r, w))
        })
        .collect();
    (measured, ties(topo, spline, corners))
}

impl KnotSurvey {
    /// The survey of the facets' measured log-ratios `measured` (by facet) and the knot
    /// surfaces' `ties`: the graded share and the largest |log-ratio| from them. The share
    /// sums by facet in the order of `measured` (the ties' order does not matter).
    pub(crate) fn from_parts(measured: Vec<Option<(f64, f64)>>, ties: Vec<Tie>) -> KnotSurvey {
        let nf = measured.len();
        let graded_share = graded_share(&mut surfaces(nf, &ties, &measured), &measured);
        let max_abs_log_ratio = measured
            .iter()
            .flatten()
            .fold(0.0f64, |a, &(m, _)| a.max(m.abs()));
        KnotSurvey {
            measured,
            ties,
            graded_share,
            max_abs_log_ratio,
        }
    }
}

/// The extraction weights of every element for `params` (uniform knots: `None`), the
/// elements to make Q2 where surfaces are split, and the figures of the knot surfaces. Knot
/// surfaces are continued across the elements that are spline elements by topology
/// (`spline[e]`); elsewhere the continuation is not defined.
pub fn knot_weights(
    mesh: &LinearMesh,
    topo: &Topology,
    spline: &[bool],
    params: &KnotParams,
) -> Knots {
    if params.intervals != KnotIntervals::Graded {
        return Knots::default();
    }
    knot_weights_from(survey(mesh, topo, spline), topo, params)
}

/// [`knot_weights`] of graded knots from the mesh's [`survey`].
pub fn knot_weights_from(survey: KnotSurvey, topo: &Topology, params: &KnotParams) -> Knots {
    let ratios = surface_ratios(survey, topo.n_elements, params);
    let weights = weights_from_ratios(topo, |f| ratios.rho[f as usize]);
    Knots {
        weights: Some(weights),
        split: if ratios.info.split_elements > 0 {
            ratios.split
        } else {
            Vec::new()
        },
        info: ratios.info,
    }
}

/// The knot surfaces' ratios of a [`KnotSurvey`] ([`surface_ratios`]).
pub(crate) struct SurfaceRatios {
    /// Per facet of the survey: `ρ(f) = ln(h_second / h_first)` of its surface (0: uniform).
    pub(crate) rho: Vec<f64>,
    /// Per element (`ne` of them): made Q2 where a knot surface is split.
    pub(crate) split: Vec<bool>,
    pub(crate) info: KnotSurfaceInfo,
}

/// The knot surfaces of `survey` over `ne` elements, split where one ratio cannot fit, and
/// each surface's ratio: the 1 / facet-size weighted mean of its facets' measured ratios,
/// summed by facet in the survey's order. Needs no topology: only facet and element numbers.
pub(crate) fn surface_ratios(survey: KnotSurvey, ne: usize, params: &KnotParams) -> SurfaceRatios {
    let KnotSurvey {
        measured,
        ties: all,
        graded_share: share,
        ..
    } = survey;
    let nf = measured.len();

    // Knot surfaces: facets tied across each spline element's neighbours; split where one
    // ratio cannot fit, and rebuilt without the split elements' ties.
    let mut split = split_elements(ne, nf, &all, &measured, params.max_spread);
    let cap = params.max_ratio.ln();
    let mut ratios = ratios_of(&all, &split, &measured, cap);
    // A surface whose ratio exceeds the cap by far cannot be reproduced by any interval it may
    // take (a boundary layer ending in one far-field cell 10⁶ times as high): the elements along
    // it are split off (C⁰ across it), as where a surface spreads too far, so the clamped ratio
    // does not distort the thin cells on its fine side, and the surfaces are rebuilt once.
    let beyond_cap = ratios.info.clamped;
    if !ratios.split_roots.is_empty() {
        for t in &all {
            for (f, e) in [(t.f, t.element), (t.f2(), t.neighbour)] {
                if ratios
                    .split_roots
                    .binary_search(&ratios.root[f as usize])
                    .is_ok()
                {
                    split[e as usize] = true;
                }
            }
        }
        ratios = ratios_of(&all, &split, &measured, cap);
    }
    drop((all, measured));
    let SurfaceRoots {
        root,
        sign,
        rho_root,
        mut info,
        ..
    } = ratios;
    info.split_elements = split.iter().filter(|&&s| s).count();
    info.graded_share = share;
    // The surfaces beyond the cap before any split (split off or clamped), not the single
    // facets a split leaves between split elements.
    info.clamped = beyond_cap;
    let rho = root
        .iter()
        .zip(&sign)
        .map(|(&r, &s)| {
            let v = rho_root[r as usize];
            if s { -v } else { v }
        })
        .collect();
    SurfaceRatios { rho, split, info }
}

/// A knot surface is split off (C⁰ across it) when its log-ratio exceeds this multiple of the
/// cap's (`--knot-max-ratio` cubed: 4096 at the default 16); below, its ratio is clamped. The
/// generated O-grids with first cell 1e-6 and growth 1.05 end in one far-field cell ~10⁶
/// times their last layer; clamped, that jump distorted every thin cell on its fine side.
/// Ratios just above the cap (a 3D sector's 18, the C-grids' 330–350) are followed better
/// clamped: split at the cap itself, a C-grid's held-back count and min scaled Jacobian got
/// worse and a rotation sector's seam rougher than its interior.
const SPLIT_LOG_RATIO: f64 = 3.0;

/// The surfaces of the ties of the elements not `split` ([`surfaces`]) and each one's ratio
/// ([`surface_ratios`]), clamped to ±`cap`; `split_roots` holds those beyond
/// [`SPLIT_LOG_RATIO`] × `cap`.
struct SurfaceRoots {
    /// Per facet: its surface's root and the facet's sign relative to it.
    root: Vec<u32>,
    sign: Vec<bool>,
    /// Per root: the surface's log-ratio (clamped).
    rho_root: Vec<f64>,
    /// Roots whose ratio lies beyond [`SPLIT_LOG_RATIO`] × the cap, ascending.
    split_roots: Vec<u32>,
    info: KnotSurfaceInfo,
}

fn ratios_of(
    all: &[Tie],
    split: &[bool],
    measured: &[Option<(f64, f64)>],
    cap: f64,
) -> SurfaceRoots {
    let nf = measured.len();
    let kept = all.iter().filter(|t| !split[t.element as usize]);
    let mut uf = surfaces(nf, kept, measured);

    // 3. One ratio per surface: the weighted mean of its facets' measured ratios.
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
    let mut info = KnotSurfaceInfo::default();
    let mut rho_root = vec![0.0f64; nf];
    let mut split_roots = Vec::new();
    for r in 0..nf {
        if weight[r] == 0.0 || root[r] as usize != r {
            continue;
        }
        info.surfaces += 1;
        let (lo, hi) = uf.lo_hi(r as u32);
        if hi >= lo {
            info.max_spread = info.max_spread.max(hi - lo);
        }
        if uf.conflict[r] {
            info.non_orientable += 1;
            continue;
        }
        let mut rho = sum[r] / weight[r];
        if rho.abs() > cap {
            info.clamped += 1;
            if rho.abs() > SPLIT_LOG_RATIO * cap {
                split_roots.push(r as u32);
            }
            rho = rho.clamp(-cap, cap);
        }
        if rho != 0.0 {
            info.graded += 1;
        }
        info.max_abs_log_ratio = info.max_abs_log_ratio.max(rho.abs());
        rho_root[r] = rho;
    }
    SurfaceRoots {
        root,
        sign,
        rho_root,
        split_roots,
        info,
    }
}

/// The extraction weights (step 4) of every element of `topo` from their facets' ratios `rho(f)`
/// (`ln(h_second / h_first)` of facet f of `topo`): `α = 1/(1 + h₋₁/h₀)`,
/// `β = 1/(1 + h₀/h₁)`; ½ on the boundary.
pub(crate) fn weights_from_ratios(
    topo: &Topology,
    rho: impl Fn(u32) -> f64 + Sync,
) -> Vec<KnotWeights> {
    let dim = topo.dim;
    let logistic = |x: f64| 1.0 / (1.0 + (-x).exp());
    (0..topo.n_elements)
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
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A xorshift generator: `next(m)` is a pseudo-random number below `m`.
    fn xorshift(mut seed: u64) -> impl FnMut(u64) -> u64 {
        move |m| {
            seed ^= seed << 13;
            seed ^= seed >> 7;
            seed ^= seed << 17;
            seed % m
        }
    }

    /// The runs joined by the workers equal the serial join, empty runs included.
    #[test]
    fn concat_matches_the_serial_join() {
        let mut next = xorshift(0x9e37_79b9_7f4a_7c15);
        let parts: Vec<Vec<u64>> = (0..200u64)
            .map(|k| (0..next(3) * next(3000)).map(|i| (k << 32) | i).collect())
            .collect();
        assert!(parts.iter().any(Vec::is_empty));
        assert_eq!(concat(&parts), parts.concat());
        assert!(concat::<u64>(&[]).is_empty());
    }

    /// On a structured 14³ grid (more elements than one run of [`ties`]) where a random half
    /// of the elements are spline elements, the ties are, in element order, side order and
    /// neighbour order, one per spline element, side and face neighbour across a face not
    /// parallel to that side, continued onto the neighbour's facet on the same side.
    #[test]
    fn ties_follow_the_elements_of_a_grid() {
        let xs: Vec<f64> = (0..=14).map(f64::from).collect();
        let mesh = crate::mesh::generate::grid_3d(&xs, &xs, &xs);
        let topo = Topology::build(&mesh);
        let ne = topo.n_elements;
        assert!(ne > TIE_RUN);
        let spline: Vec<bool> = (0..ne).map(|e| (e * 2_654_435_761) % 7 < 4).collect();
        let corners = Corners {
            mesh: &mesh,
            unglued: None,
            global: None,
        };
        let got: Vec<(u32, u32, u32, u32)> = ties(&topo, &spline, corners)
            .iter()
            .map(|t| (t.element, t.neighbour, t.f, t.f2()))
            .collect();
        let mut want = Vec::new();
        for e in (0..ne).filter(|&e| spline[e]) {
            for side in 0..6 {
                for other in (0..6).filter(|o| o / 2 != side / 2) {
                    let n = topo.neighbor(e, other);
                    if n != NONE {
                        let (f, f2) = (
                            topo.element_facet(e, side),
                            topo.element_facet(n as usize, side),
                        );
                        want.push((e as u32, n, f, f2));
                    }
                }
            }
        }
        assert_eq!(got, want);
    }

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

    /// Against a brute force that relabels a whole set on every union (the root of the union
    /// of `a`'s and `b`'s sets is `a`'s root, as the surfaces' sums and ranges are taken in
    /// its orientation): on random signed ties, every facet's root and sign, every root's
    /// range and conflict flag, and the ranges a tie would form, agree exactly.
    #[test]
    fn signed_union_find_matches_relabelling() {
        let n = 300usize;
        let mut next = xorshift(0x2545_f491_4f6c_dd1d);
        let values: Vec<Option<f64>> = (0..n)
            .map(|_| (next(4) != 0).then(|| next(2001) as f64 / 1000.0 - 1.0))
            .collect();
        let mut uf = SignedUnionFind::with_values(values.iter().copied());
        let (mut root, mut sign, mut conflict) =
            ((0..n).collect::<Vec<_>>(), vec![false; n], vec![false; n]);
        let range_of = |root: &[usize], sign: &[bool], r: usize| {
            (0..n)
                .filter(|&x| root[x] == r)
                .filter_map(|x| values[x].map(|v| if sign[x] { -v } else { v }))
                .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), v| {
                    (lo.min(v), hi.max(v))
                })
        };
        for _ in 0..400 {
            let (a, b, opposite) = (
                next(n as u64) as usize,
                next(n as u64) as usize,
                next(2) == 1,
            );
            let (ra, rb) = (root[a], root[b]);
            let flip = sign[a] ^ sign[b] ^ opposite;
            let expected = if ra == rb {
                range_of(&root, &sign, ra)
            } else {
                let (lo, hi) = range_of(&root, &sign, ra);
                let (blo, bhi) = range_of(&root, &sign, rb);
                let (blo, bhi) = if flip { (-bhi, -blo) } else { (blo, bhi) };
                (lo.min(blo), hi.max(bhi))
            };
            let got = uf.merged_range(a as u32, b as u32, opposite);
            assert_eq!(format!("{got:?}"), format!("{expected:?}"));
            uf.union(a as u32, b as u32, opposite);
            if ra == rb {
                conflict[ra] |= flip;
            } else {
                for (r, s) in root.iter_mut().zip(sign.iter_mut()) {
                    if *r == rb {
                        *r = ra;
                        *s ^= flip;
                    }
                }
                conflict[ra] |= conflict[rb];
            }
            for (x, (&r, &s)) in root.iter().zip(&sign).enumerate() {
                assert_eq!(uf.find(x as u32), (r as u32, s), "facet {x}");
            }
            for r in (0..n).filter(|&r| root[r] == r) {
                let (lo, hi) = uf.lo_hi(r as u32);
                assert_eq!(
                    format!("{:?}", (lo, hi)),
                    format!("{:?}", range_of(&root, &sign, r))
                );
                assert_eq!(uf.conflict[r], conflict[r], "root {r}");
            }
        }
        assert!(root.iter().filter(|&&r| r == root[0]).count() > n / 2);
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
