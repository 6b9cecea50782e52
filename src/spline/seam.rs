//! Periodic seams identified in the spline space.
//!
//! Input: the linear mesh, its topology and the verified periodic pairs
//! ([`crate::mesh::periodic::PeriodicPair`]). [`glue`] gives the mesh whose image-side vertices
//! are replaced by their masters' (translations and rotations; chains of pairs, as at the
//! corners of a doubly periodic box, glue to one representative) and its topology: the seam facets are
//! interior there, so the stencils of [`super::SplineSpace`] built on it reach across the seam
//! and the two sides share control points. [`unwrap`] then puts the space back onto the
//! input's geometry, element by element:
//!
//! * every control point key is renamed to the input's entity of one element holding it (its
//!   *home*) and starts at that entity's vertex average, as without seams;
//! * an element whose stencil reaches a control point across a seam sees it moved by the
//!   known period: the shift `x_e(g) − x_h(g)` of a glued vertex g common to the element and
//!   the point's home, snapped to the nearest combination `Σ k_i t_i` of the translations.
//!   The shifts enter [`super::Extraction::node_shifts`] (the rows `E_e` sum to 1 and are
//!   unchanged), so the least-squares matrix is that of the glued space and only the nets,
//!   and through them the fit's right-hand side, carry the shift.
//! * across a rotation seam the element sees the point through the rigid map R P + t of the
//!   pairs' transforms (and their inverses, composed) that carries the common glued vertices
//!   from the home's positions to the element's: t joins the shifts, and R, where it is not
//!   the identity, [`super::Extraction::frames`]. Such an element's net is no longer one
//!   linear map of each coordinate: the fit couples them (`fit::rotated`).
//!
//! [`interior_view`] gives the input's topology with the seam facets interior, on which the
//! pipeline builds everything fitted to the boundary (targets, features, kinks, weights).
//! [`knot_weights`] gives graded knot intervals of the glued space: its knot surfaces run
//! across the seams, each element measured on its own input vertices.
//!
//! Invariants: where [`glue`] returns a mesh, its topology is manifold and every seam facet is
//! interior; [`unwrap`] refuses (and the caller keeps the sides apart) when a shift is not a
//! combination of the translations to `SHIFT_REL_TOL` of the period, or two common vertices
//! disagree (translations), or when no such rigid map carries them (rotations).
//! [`glue_translations`] glues the translations only (where the rotation pairs' glued mesh is
//! not manifold); [`glue_share`] glues a rank's sub-mesh as
//! either glues the whole mesh (the distributed CG couples the coordinates across rotations).

use super::intervals::{KnotIntervals, KnotParams, KnotSurvey, Knots};
use super::{ControlPoint, SplineSpace};
use crate::math::linalg::DVec3;
use crate::mesh::LinearMesh;
use crate::mesh::periodic::{PeriodicPair, Rigid};
use crate::mesh::topology::{NONE, Topology};

/// Largest distance of a measured shift from its combination of the translations, relative to
/// the shortest translation.
const SHIFT_REL_TOL: f64 = 1e-6;

/// The input with its translation-periodic sides glued.
#[derive(Clone, Debug)]
pub struct Glued {
    /// The input's coordinates with every element's image-side vertices replaced by their
    /// representatives (the masters); image-side vertices are used by no element.
    pub mesh: LinearMesh,
    /// The topology of `mesh`.
    pub topo: Topology,
    /// The periods: the translation of each glued translation pair.
    pub translations: Vec<[f64; 3]>,
    /// The transforms of the glued rotation pairs (empty: translations only, see
    /// [`glue_translations`]).
    pub rotations: Vec<Rigid>,
    /// The order in which [`unwrap`] picks a control point's home among the elements holding
    /// its entity (the lowest): each element's global index on a rank's sub-mesh, so that
    /// every rank picks the same home whatever its local numbering; `None`: the element's
    /// index (the serial mesh).
    pub element_order: Option<Vec<u64>>,
}

fn find(parent: &mut [u32], mut v: u32) -> u32 {
    while parent[v as usize] != v {
        let p = parent[v as usize];
        parent[v as usize] = parent[p as usize];
        v = p;
    }
    v
}

/// The knot intervals of `params` for the space built on the glued mesh `g` of `input`
/// (uniform knots: none): the knot surfaces are continued across the seams on the glued
/// topology and each element's extents are measured on its own vertices in `input`
/// ([`super::intervals::survey_glued`]), so a surface crossing a seam gets one ratio and the
/// seam stays C¹ with graded knots. The weights and split elements are per element, in the
/// input's numbering (the glued mesh keeps its elements and their corner order).
pub fn knot_weights(input: &LinearMesh, g: &Glued, params: &KnotParams) -> Knots {
    if params.intervals != KnotIntervals::Graded {
        return Knots::default();
    }
    super::intervals::knot_weights_from(knot_survey(input, g), &g.topo, params)
}

/// The knot surfaces of the glued mesh `g` of `input` ([`knot_weights`]), for
/// [`super::intervals::knot_weights_from`].
pub fn knot_survey(input: &LinearMesh, g: &Glued) -> KnotSurvey {
    let spline: Vec<bool> = super::classify::classify(&g.mesh, &g.topo)
        .iter()
        .map(|c| c.is_spline())
        .collect();
    super::intervals::survey_glued(input, &g.mesh, &g.topo, &spline)
}

/// The input with the periodic pairs among `pairs` glued (translations and rotations), or
/// `None` when there is none or the glued mesh is not manifold (a period of fewer elements
/// than a stencil needs, for instance): the sides are then curved apart and made images
/// afterwards.
pub fn glue(mesh: &LinearMesh, pairs: &[PeriodicPair]) -> Option<Glued> {
    glue_pairs(mesh, pairs, None, true)
}

/// [`glue`] of the translation pairs among `pairs` only (the rotation pairs stay apart): for
/// the consumers that take a control point as the same linear map of every coordinate.
pub fn glue_translations(mesh: &LinearMesh, pairs: &[PeriodicPair]) -> Option<Glued> {
    glue_pairs(mesh, pairs, None, false)
}

/// How a rank's sub-mesh is glued ([`glue_share`]).
pub struct ShareOrder<'a> {
    /// The global rank of each vertex (its node tag): a class of glued vertices is
    /// represented by its lowest, as on the whole mesh.
    pub vertex: &'a [u64],
    /// The global index of each element ([`Glued::element_order`]).
    pub element: &'a [u64],
    /// Per vertex: it belongs to one of the rank's own elements. Only the non-manifold
    /// entities, self-neighbours and collapsed elements among these refuse the gluing: the
    /// cut fringe of a ghost layer may look non-manifold where the whole mesh is not.
    pub near: &'a [bool],
}

/// [`glue`] (`rotations`) or [`glue_translations`] of the whole mesh (`share`: `None`) or of
/// a rank's ghosted sub-mesh, its pairs' vertex maps restricted to the vertices it holds
/// (`share`: see [`ShareOrder`]); the distributed fit couples the coordinates across the
/// rotations (`distributed::cg`).
pub fn glue_share(
    mesh: &LinearMesh,
    pairs: &[PeriodicPair],
    share: Option<&ShareOrder>,
    rotations: bool,
) -> Option<Glued> {
    glue_pairs(mesh, pairs, share, rotations)
}

/// [`glue_share`]: the rotation pairs glued too when `rotations`.
fn glue_pairs(
    mesh: &LinearMesh,
    pairs: &[PeriodicPair],
    share: Option<&ShareOrder>,
    rotations: bool,
) -> Option<Glued> {
    let glued_pairs: Vec<&PeriodicPair> = pairs
        .iter()
        .filter(|p| rotations || p.transform.is_translation())
        .collect();
    if glued_pairs.is_empty() {
        return None;
    }
    let mut parent: Vec<u32> = (0..mesh.n_vertices() as u32).collect();
    for p in &glued_pairs {
        for &[b, a] in &p.vertex_map {
            let (rb, ra) = (find(&mut parent, b), find(&mut parent, a));
            // The smaller id represents the class: a master unless the chain says otherwise.
            let rank = |v: u32| share.map_or(v as u64, |o| o.vertex[v as usize]);
            let (lo, hi) = if rank(ra) <= rank(rb) {
                (ra, rb)
            } else {
                (rb, ra)
            };
            if lo != hi {
                parent[hi as usize] = lo;
            }
        }
    }
    let rep: Vec<u32> = (0..parent.len() as u32)
        .map(|v| find(&mut parent, v))
        .collect();
    let mut glued = mesh.clone();
    for v in glued
        .elements
        .iter_mut()
        .chain(glued.tagged_facets.iter_mut())
    {
        *v = rep[*v as usize];
    }
    let topo = Topology::build(&glued);
    let ne = topo.n_elements;
    let npe = mesh.nodes_per_element();
    // The elements and entities that decide (a share's: those among its own vertices).
    let near: Option<Vec<bool>> = share.map(|o| {
        let mut near = vec![false; mesh.n_vertices()];
        for (v, &n) in o.near.iter().enumerate() {
            if n {
                near[rep[v] as usize] = true;
            }
        }
        near
    });
    let counts = |vs: &[u32]| {
        near.as_ref()
            .is_none_or(|n| vs.iter().all(|&v| n[v as usize]))
    };
    let element_counts = |e: usize| counts(&glued.elements[e * npe..(e + 1) * npe]);
    let nm = &topo.non_manifold;
    let facet = |f: u32| -> &[u32] { topo.facet_vertices(f as usize) };
    let non_manifold = nm.facets.iter().any(|&f| counts(facet(f)))
        || nm.edges.iter().any(|&d| counts(&topo.edges[d as usize]))
        || nm.vertices.iter().any(|&v| counts(&[v]));
    let self_neighbour = (0..ne)
        .any(|e| element_counts(e) && (0..topo.sides()).any(|s| topo.neighbor(e, s) == e as u32));
    if non_manifold || self_neighbour {
        return None;
    }
    // An element whose corners glue together is collapsed: keep the sides apart.
    for e in (0..ne).filter(|&e| element_counts(e)) {
        let mut vs = glued.elements[e * npe..(e + 1) * npe].to_vec();
        vs.sort_unstable();
        if vs.windows(2).any(|w| w[0] == w[1]) {
            return None;
        }
    }
    Some(Glued {
        mesh: glued,
        topo,
        translations: glued_pairs
            .iter()
            .filter(|p| p.transform.is_translation())
            .map(|p| p.transform.translation)
            .collect(),
        rotations: glued_pairs
            .iter()
            .filter(|p| !p.transform.is_translation())
            .map(|p| p.transform)
            .collect(),
        element_order: share.map(|o| o.element.to_vec()),
    })
}

/// The input's topology as the glued mesh sees it: the seam facets (boundary facets of the
/// input that are interior once glued) are interior, with the element across the seam as
/// their second element ([`Topology::with_interior_facets`]); the geometry stays the input's.
/// Everything fitted to the boundary (smooth targets, features, kinks, fit weights, misfit
/// checks, the blend's target map) is built on it, so the seam is treated as the interior.
#[derive(Clone, Debug)]
pub struct SeamView {
    /// The input's topology with the seam facets interior.
    pub topo: Topology,
    /// Vertices still on the boundary that lie on a seam facet: where a wall meets the seam.
    /// Their boundary continues across the seam, on the other side's vertices, so they end
    /// an open boundary curve (2D) or surface (3D) here and are no kink.
    pub seam_ends: Vec<bool>,
    /// Per boundary facet of `topo`, its index among the input's boundary facets.
    pub boundary_rows: Vec<u32>,
    /// Per vertex, where the wall curve (2D) or surface (3D) cut at it by a seam goes on:
    /// the other side's vertex on the same glued vertex, and the rigid map carrying that
    /// side onto this one, so the smooth targets see the wall on both sides (`None` at every
    /// other vertex).
    pub wall_partners: Vec<Option<(u32, Rigid)>>,
    /// Every vertex of a seam facet paired with each vertex of the other side on the same
    /// glued vertex: (v, w, t) with t the rigid map carrying w's side onto v's (x_v = t x_w),
    /// in both directions, sorted. The interior inheritance of the smooth targets walks
    /// across the seam along them (`fit::SmoothTargets::build_shared`).
    pub seam_links: Vec<(u32, u32, Rigid)>,
}

/// [`SeamView`] of the input (`mesh`, `topo`) glued as `glued`.
pub fn interior_view(mesh: &LinearMesh, topo: &Topology, glued: &Glued) -> SeamView {
    let gt = &glued.topo;
    let across: Vec<(u32, u32, u8)> = topo
        .boundary_facets
        .iter()
        .filter_map(|&f| {
            let e = topo.facet_elements[f as usize][0];
            let s = topo.facet_sides[f as usize][0];
            let gf = gt.element_facet(e as usize, s as usize) as usize;
            let ([a, b], [sa, sb]) = (gt.facet_elements[gf], gt.facet_sides[gf]);
            if b == NONE {
                return None;
            }
            Some(if a == e && sa == s {
                (f, b, sb)
            } else {
                (f, a, sa)
            })
        })
        .collect();
    let view = topo.with_interior_facets(mesh, &across);
    let mut seam_ends = vec![false; topo.n_vertices];
    for &(f, _, _) in &across {
        for &v in topo.facet_vertices(f as usize) {
            seam_ends[v as usize] = view.vertex_on_boundary[v as usize];
        }
    }
    let boundary_rows = (0..topo.boundary_facets.len() as u32)
        .filter(|&i| {
            let f = topo.boundary_facets[i as usize] as usize;
            view.facet_elements[f][1] == NONE
        })
        .collect();
    let mut seam_links = seam_links(mesh, topo, glued, &across);
    // A wall end's partner: the last seam facet's (a corner of a doubly periodic box has
    // several).
    let mut wall_partners = vec![None; mesh.n_vertices()];
    for &(v, w, t) in &seam_links {
        if seam_ends[v as usize] {
            wall_partners[v as usize] = Some((w, t));
        }
    }
    // A vertex is met once per seam facet holding it: each pair once.
    seam_links.sort_by_key(|&(v, w, _)| (v, w));
    seam_links.dedup_by_key(|&mut (v, w, _)| (v, w));
    SeamView {
        topo: view,
        seam_ends,
        boundary_rows,
        wall_partners,
        seam_links,
    }
}

/// [`SeamView::seam_links`], facet by facet of `across` (a facet of the input with the
/// element and side across the seam): each vertex `v` of the facet is paired with the vertex
/// of the facet across that glues to the same vertex, through the map of [`group`] that
/// carries the facet across onto v's (to `SHIFT_REL_TOL` of the facet's length).
fn seam_links(
    mesh: &LinearMesh,
    topo: &Topology,
    glued: &Glued,
    across: &[(u32, u32, u8)],
) -> Vec<(u32, u32, Rigid)> {
    let mut glued_of = vec![u32::MAX; mesh.n_vertices()];
    for e in 0..mesh.n_elements() {
        for (&v, &g) in mesh.element(e).iter().zip(glued.mesh.element(e)) {
            glued_of[v as usize] = g;
        }
    }
    let maps = group(glued);
    let x = |v: u32| DVec3::from(mesh.coords[v as usize]);
    let mut out: Vec<(u32, u32, Rigid)> = Vec::new();
    for &(f, b, sb) in across {
        let here = topo.facet_vertices(f as usize);
        let there = topo.facet_vertices(topo.element_facet(b as usize, sb as usize) as usize);
        // The facet's vertices paired with those across (same glued vertex).
        let pairs: Vec<(u32, u32)> = here
            .iter()
            .filter_map(|&v| {
                let w = there
                    .iter()
                    .copied()
                    .find(|&w| glued_of[w as usize] == glued_of[v as usize])?;
                Some((v, w))
            })
            .collect();
        if pairs.len() != here.len() {
            continue;
        }
        let size = (x(here[0]) - x(here[here.len() - 1])).length();
        let miss = |t: &Rigid| {
            pairs
                .iter()
                .map(|&(v, w)| (DVec3::from(t.apply(mesh.coords[w as usize])) - x(v)).length())
                .fold(0.0, f64::max)
        };
        let Some(t) = maps
            .iter()
            .min_by(|a, b| miss(a).total_cmp(&miss(b)))
            .filter(|t| miss(t) <= SHIFT_REL_TOL * size)
        else {
            continue;
        };
        out.extend(pairs.iter().map(|&(v, w)| (v, w, *t)));
    }
    out
}

/// Element `h`'s input vertex at its glued corner `g`.
fn original_of(mesh: &LinearMesh, glued: &LinearMesh, h: usize, g: u32) -> u32 {
    let c = glued
        .element(h)
        .iter()
        .position(|&v| v == g)
        .expect("the home element holds the entity");
    mesh.element(h)[c]
}

/// A glued-topology key's home element, its key in the input's topology and that entity's
/// input vertices.
fn home_of(
    mesh: &LinearMesh,
    topo: &Topology,
    glued: &Glued,
    key: ControlPoint,
) -> (usize, ControlPoint, Vec<u32>) {
    use ControlPoint::*;
    let gt = &glued.topo;
    // The lowest element holding the entity (the first in the serial topology's lists).
    let order = |e: u32| {
        glued
            .element_order
            .as_ref()
            .map_or(e as u64, |o| o[e as usize])
    };
    let facet_home = |f: u32| {
        let ([a, b], [sa, sb]) = (gt.facet_elements[f as usize], gt.facet_sides[f as usize]);
        let (h, side) = if b != NONE && order(b) < order(a) {
            (b as usize, sb as usize)
        } else {
            (a as usize, sa as usize)
        };
        let of = topo.element_facet(h, side);
        (h, of, topo.facet_vertices(of as usize).to_vec())
    };
    match key {
        Cell(e) | Q2Centre(e) => (e as usize, key, mesh.element(e as usize).to_vec()),
        BFace(f) | Q2Face(f) => {
            let (h, of, vs) = facet_home(f);
            let k = if matches!(key, BFace(_)) {
                BFace(of)
            } else {
                Q2Face(of)
            };
            (h, k, vs)
        }
        BEdge(ed) | Q2Edge(ed) => {
            let (h, oe) = if gt.dim == 2 {
                let (h, of, _) = facet_home(ed);
                (h, of)
            } else {
                let a = gt.edges[ed as usize][0] as usize;
                gt.elements_at_vertex(a)
                    .iter()
                    .filter_map(|&h| {
                        let h = h as usize;
                        (0..12)
                            .find(|&le| gt.element_edges[h * 12 + le] == ed)
                            .map(|le| (h, topo.element_edges[h * 12 + le]))
                    })
                    .min_by_key(|&(h, _)| order(h as u32))
                    .expect("an edge has an element")
            };
            let k = if matches!(key, BEdge(_)) {
                BEdge(oe)
            } else {
                Q2Edge(oe)
            };
            (h, k, topo.edges[oe as usize].to_vec())
        }
        BVertex(v) | Q2Vertex(v) => {
            let h = *gt
                .elements_at_vertex(v as usize)
                .iter()
                .min_by_key(|&&h| order(h))
                .expect("a vertex has an element") as usize;
            let ov = original_of(mesh, &glued.mesh, h, v);
            let k = if matches!(key, BVertex(_)) {
                BVertex(ov)
            } else {
                Q2Vertex(ov)
            };
            (h, k, vec![ov])
        }
    }
}

fn centre(mesh: &LinearMesh, vs: &[u32]) -> DVec3 {
    vs.iter()
        .map(|&v| DVec3::from(mesh.coords[v as usize]))
        .sum::<DVec3>()
        / vs.len() as f64
}

/// The combinations Σ k_i t_i, k_i ∈ {−1, 0, 1}, of the periods.
fn lattice(translations: &[[f64; 3]]) -> Vec<DVec3> {
    let mut out = vec![DVec3::ZERO];
    for t in translations {
        let t = DVec3::from(*t);
        out = out.iter().flat_map(|&s| [s - t, s, s + t]).collect();
    }
    out
}

/// The rigid maps Π T_i^{k_i}, k_i ∈ {−1, 0, 1}, of the glued pairs' transforms (translations
/// and rotations): the maps that may carry a control point's home to an element across one
/// seam of each pair.
fn group(glued: &Glued) -> Vec<Rigid> {
    let mut out = vec![Rigid::translation([0.0; 3])];
    let pairs = glued
        .translations
        .iter()
        .map(|&t| Rigid::translation(t))
        .chain(glued.rotations.iter().copied());
    for t in pairs {
        let inv = t.inverse();
        out = out
            .iter()
            .flat_map(|s| [inv.after(s), *s, t.after(s)])
            .collect();
    }
    out
}

/// How element `e` sees a control point homed in element `h`: the map carrying the point
/// from its home's side to `e`'s.
type Frame = (DVec3, Option<[[f64; 3]; 3]>);

/// [`Frame`] of a control point homed in `h` for element `e` when rotation pairs are glued:
/// the map of [`group`] that carries every glued vertex common to `e` and `h` from its
/// position in `h` to its position in `e` (to `SHIFT_REL_TOL` of `e`'s size); among several
/// (vertices on a rotation axis), and with no common vertex, the one bringing the home
/// entity's centre `cp` nearest `e`'s.
fn rigid_frame(
    mesh: &LinearMesh,
    gm: &LinearMesh,
    group: &[Rigid],
    (e, h): (usize, usize),
    cp: DVec3,
) -> Option<Frame> {
    let (ge, oe, gh, oh) = (
        gm.element(e),
        mesh.element(e),
        gm.element(h),
        mesh.element(h),
    );
    let x = |v: u32| DVec3::from(mesh.coords[v as usize]);
    let ce = centre(mesh, oe);
    let size = oe.iter().map(|&v| (x(v) - ce).length()).fold(0.0, f64::max);
    let tol = SHIFT_REL_TOL * size;
    let common: Vec<(DVec3, DVec3)> = ge
        .iter()
        .enumerate()
        .filter_map(|(i, g)| {
            let j = gh.iter().position(|y| y == g)?;
            Some((x(oh[j]), x(oe[i])))
        })
        .collect();
    let fits = |t: &&Rigid| {
        common
            .iter()
            .all(|(a, b)| (DVec3::from(t.apply(a.to_array())) - *b).length() <= tol)
    };
    let near = |t: &Rigid| (DVec3::from(t.apply(cp.to_array())) - ce).length();
    let t = group
        .iter()
        .filter(fits)
        .min_by(|a, b| near(a).total_cmp(&near(b)))?;
    let rotation = (!t.is_translation()).then_some(t.rotation);
    Some((DVec3::from(t.translation), rotation))
}

/// Put `space`, built on `glued`, back onto the input's geometry (module docs): keys and
/// initial control points of the input's entities, and the seam shifts (and, across rotation
/// seams, the rotations: [`super::Extraction::frames`]) of the elements whose stencils cross
/// a seam. Returns the number of elements with a shift, or why the seams cannot be
/// identified (then `space` must not be used).
pub fn unwrap(
    space: &mut SplineSpace,
    mesh: &LinearMesh,
    topo: &Topology,
    glued: &Glued,
) -> Result<usize, String> {
    use rayon::prelude::*;
    let homes: Vec<(usize, ControlPoint, Vec<u32>)> = space
        .control_point_keys
        .par_iter()
        .map(|&k| home_of(mesh, topo, glued, k))
        .collect();
    let lattice = lattice(&glued.translations);
    let group = (!glued.rotations.is_empty()).then(|| group(glued));
    let period = glued
        .translations
        .iter()
        .map(|t| DVec3::from(*t).length())
        .fold(f64::INFINITY, f64::min);
    let tol = SHIFT_REL_TOL * period;
    let snap = |d: DVec3| -> Option<DVec3> {
        let s = lattice
            .iter()
            .copied()
            .min_by(|a, b| (*a - d).length().total_cmp(&(*b - d).length()))?;
        ((s - d).length() <= tol).then_some(s)
    };
    let gm = &glued.mesh;
    // The translation of a control point homed in `h` as element `e` sees it.
    let shift = |e: usize, c: u32, h: usize| -> Result<DVec3, String> {
        let (ge, oe) = (gm.element(e), mesh.element(e));
        let (gh, oh) = (gm.element(h), mesh.element(h));
        let mut s: Option<DVec3> = None;
        for (i, g) in ge.iter().enumerate() {
            let Some(j) = gh.iter().position(|x| x == g) else {
                continue;
            };
            let d =
                DVec3::from(mesh.coords[oe[i] as usize]) - DVec3::from(mesh.coords[oh[j] as usize]);
            let d = snap(d)
                .ok_or_else(|| format!("element {e} sees control point {c} moved by no period"))?;
            if s.is_some_and(|s| s != d) {
                return Err(format!(
                    "element {e} meets the home of control point {c} across two seams"
                ));
            }
            s = Some(d);
        }
        // No common vertex (a stencil reaching further): the period that brings the point
        // nearest to the element.
        Ok(s.unwrap_or_else(|| {
            let (ce, cp) = (centre(mesh, oe), centre(mesh, &homes[c as usize].2));
            lattice
                .iter()
                .copied()
                .min_by(|a, b| (cp + *a - ce).length().total_cmp(&(cp + *b - ce).length()))
                .unwrap_or(DVec3::ZERO)
        }))
    };
    let frame = |e: usize, c: u32| -> Result<Frame, String> {
        let h = homes[c as usize].0;
        match &group {
            None => Ok((shift(e, c, h)?, None)),
            Some(group) => {
                let cp = centre(mesh, &homes[c as usize].2);
                rigid_frame(mesh, gm, group, (e, h), cp).ok_or_else(|| {
                    format!("element {e} sees control point {c} moved by no periodic transform")
                })
            }
        }
    };
    let ext = &space.extraction;
    let n = ext.n_local();
    type Seen = (Option<[[f64; 3]; 27]>, Vec<(u32, [[f64; 3]; 3])>);
    let shifts: Vec<Result<Seen, String>> = (0..space.n_elements())
        .into_par_iter()
        .map(|e| {
            let mut out = [[0.0; 3]; 27];
            let mut any = false;
            let mut cache: Vec<(u32, Frame)> = Vec::new();
            for (l, &node) in ext.element_nodes(e).iter().enumerate().take(n) {
                for (c, w) in ext.node_entries(node) {
                    let (s, _) = match cache.iter().find(|p| p.0 == c) {
                        Some(p) => p.1,
                        None => {
                            let f = frame(e, c)?;
                            cache.push((c, f));
                            f
                        }
                    };
                    if s != DVec3::ZERO {
                        any = true;
                        let x = DVec3::from(out[l]) + s * w;
                        out[l] = x.to_array();
                    }
                }
            }
            let rotated = cache
                .into_iter()
                .filter_map(|(c, (_, r))| r.map(|r| (c, r)))
                .collect();
            Ok((any.then_some(out), rotated))
        })
        .collect();
    let mut shift_of = vec![NONE; space.n_elements()];
    let mut node_shifts = Vec::new();
    let mut frame_of = vec![NONE; space.n_elements()];
    let mut frames = Vec::new();
    for (e, s) in shifts.into_iter().enumerate() {
        let (s, rotated) = s?;
        if let Some(s) = s {
            shift_of[e] = node_shifts.len() as u32;
            node_shifts.push(s);
        }
        if !rotated.is_empty() {
            frame_of[e] = frames.len() as u32;
            frames.push(rotated);
        }
    }
    let count = node_shifts.len();
    for (i, (_, key, vs)) in homes.into_iter().enumerate() {
        space.control_point_keys[i] = key;
        space.control_points[i] = centre(mesh, &vs).to_array();
    }
    if count > 0 {
        space.extraction.shift_of = shift_of;
        space.extraction.node_shifts = node_shifts;
    }
    if !frames.is_empty() {
        space.extraction.frame_of = frame_of;
        space.extraction.frames = frames;
    }
    Ok(count)
}
