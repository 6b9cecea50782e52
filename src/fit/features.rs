//! The fit's treatment of sharp features ([`crate::mesh::features`]).
//!
//! Input: the [`Features`] of the input mesh. Three things depend on them:
//! * **Targets** ([`FeatureModels`]): the smooth-boundary reconstruction ([`super::smooth`])
//!   never averages across a feature. A vertex on a feature edge carries one quadric model per
//!   patch around it, fitted to that patch's faces only, and — where exactly two feature edges
//!   meet — a curve model: the parabola through the vertex and its two neighbours along the
//!   feature polyline (in their plane). Face samples use the models of their patch, samples on
//!   a feature edge the curve models, samples on a non-feature boundary edge those of the
//!   patch of its faces; corners (≠ 2 feature edges) have no curve model, so targets next to
//!   them follow the other end's model or the chord.
//! * **Weights** ([`sample_mask`]): corner samples at feature vertices take
//!   [`super::FitWeights::feature`].
//! * **Planar patches** ([`project_onto_planes`]): after the solve, every control point of a
//!   boundary entity is projected onto the planes of the planar patches it belongs to (their
//!   intersection line or point where there are several), so planar input faces stay exactly
//!   planar. The initial control points lie on those planes already (vertex averages of
//!   coplanar vertices), so every step of the line search keeps them there.

use super::smooth::{
    Height, HigherModel, InheritShare, Paths, RingScratch, SeamLink, SeamSides, Source,
    VertexModel, adjacency, dedup_points, fan_across, fan_model, fit_parabola, nearest_shared,
    quad_fan_model, refine_model, refine_patch_model, seam_adjacency, two_ring_from,
};
use crate::math::linalg::DVec3;
use crate::math::reference::HEX_VERTEX_PARAMS;
use crate::mesh::features::{Features, RIM_Q2_MIN_ASPECT};
use crate::mesh::periodic::Rigid;
use crate::mesh::{LinearMesh, Topology};
use crate::spline::{ControlPoint, SplineSpace};
use std::collections::HashMap;

/// Per-patch and per-curve boundary models at feature vertices.
#[derive(Clone, Debug, Default)]
pub struct FeatureModels {
    /// (vertex, patch) → the quadric model of that patch at that vertex.
    patch: HashMap<(u32, u32), VertexModel>,
    /// Vertex with two feature edges → the model of the feature curve through it.
    curve: HashMap<u32, VertexModel>,
    /// The cubic and quartic terms of the patch models refitted as height functions over the
    /// patch's two rings (see [`super::smooth`]), where they could be.
    patch_higher: HashMap<(u32, u32), HigherModel>,
    /// Curve models refitted as height functions over two neighbours each way along the
    /// feature curve, for the samples on feature edges only (inside the mesh and in planar
    /// patches the parabola is kept next to cells of comparable size).
    curve_higher: HashMap<u32, (VertexModel, HigherModel)>,
    /// Rims next to thin cells (a boundary layer's wall rim, [`RIM_Q2_MIN_ASPECT`]): the
    /// refit's higher terms, which every sample at the vertex takes with its refitted curve
    /// model (`curve`), on the rim, the wall, the caps and inside, as the samples of a 2D
    /// boundary layer take their wall vertex's: a thin cell's inner side then moves with its
    /// wall side (a parabola inside under a more accurate rim folds the cell).
    rim_higher: HashMap<u32, HigherModel>,
    /// Feature vertices on a thin rim: two neighbours along the curve (across a periodic seam
    /// too, as for the curve models) and a mesh edge shorter than [`RIM_Q2_MIN_ASPECT`] × the
    /// curve's edges there. Their corner samples take [`thin_rim_weight`], not the feature
    /// weight ([`thin_rim_mask`]).
    thin_rim: Vec<u32>,
    /// The in-plane models' higher terms, inherited from thin rims (`rim_higher`).
    pub(crate) in_plane_higher: HashMap<u32, HigherModel>,
    /// Boundary facet id → patch (boundary facets at feature vertices).
    facet_patch: HashMap<u32, u32>,
    /// Boundary edge id → patch of its faces (non-feature edges at feature vertices).
    edge_patch: HashMap<u32, u32>,
    edge_mask: Vec<bool>,
    /// Non-feature vertices of planar patches (2D: straight chains) → their model within the
    /// plane, replacing the flat model of their fan (see module docs).
    pub(crate) in_plane: HashMap<u32, VertexModel>,
    /// The rim's edge length ℓ at the source of each inherited in-plane model (the scale of
    /// [`super::smooth::MODEL_REACH`]).
    pub(crate) in_plane_scale: HashMap<u32, f64>,
}

/// Where a sample lies on the boundary.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum BoundaryEntity {
    Facet(u32),
    /// 3D boundary edge.
    Edge(u32),
}

impl FeatureModels {
    /// Models at the feature vertices of `features`; `cos_max` bounds the angle between a
    /// patch's facet normals and the patch normal at a vertex (beyond it: no model); the
    /// in-plane models of planar patches decay over `decay` × the rim's edge length. `fan`
    /// holds the boundary facets at each vertex and `smooth` the smooth vertices' models,
    /// through which the patch models' second rings are reached; `share` and `partners` as in
    /// [`super::SmoothTargets::build_shared`]: in 3D, where a feature curve ends on a
    /// periodic seam (a rim meeting it), its curve and the patches at its end go on on the
    /// partner's side, carried over by the periodic map, so the vertex's models are the ones
    /// of the glued boundary, as along the rest of the rim. A planar patch cut by a seam takes
    /// its in-plane models across it along `links` as the interior does.
    #[allow(clippy::too_many_arguments)]
    pub fn build(
        mesh: &LinearMesh,
        topo: &Topology,
        features: &Features,
        cos_max: f64,
        decay: f64,
        fan_all: &[Vec<u32>],
        smooth: &[Option<VertexModel>],
        share: Option<&dyn InheritShare>,
        (partners, links): SeamSides,
    ) -> FeatureModels {
        let mut out = FeatureModels {
            edge_mask: features.edge_mask.clone(),
            ..Default::default()
        };
        if topo.dim != 3 {
            // Straight chains: exactly flat models, so their targets stay on the line.
            for (i, &f) in topo.boundary_facets.iter().enumerate() {
                if let Some((n, _)) = features.planes[features.facet_patch[i] as usize] {
                    for &v in topo.facet_vertices(f as usize) {
                        if !features.vertex_mask[v as usize] {
                            out.in_plane.insert(v, flat(n));
                        }
                    }
                }
            }
            return out;
        }
        let x = |v: u32| DVec3::from(mesh.coords[v as usize]);
        let mut fan: HashMap<u32, Vec<(u32, u32)>> = HashMap::new();
        for (i, &f) in topo.boundary_facets.iter().enumerate() {
            let p = features.facet_patch[i];
            let q = topo.faces[f as usize];
            if q.iter().any(|&v| features.vertex_mask[v as usize]) {
                out.facet_patch.insert(f, p);
                let e = topo.facet_elements[f as usize][0] as usize;
                let side = topo.facet_sides[f as usize][0] as usize;
                for ed in crate::mesh::features::face_edges(topo, e, side) {
                    if !features.edge_mask[ed as usize] {
                        out.edge_patch.insert(ed, p);
                    }
                }
            }
            for &v in &q {
                if features.vertex_mask[v as usize] {
                    fan.entry(v).or_default().push((f, p));
                }
            }
        }
        // The shortest mesh edge at each vertex.
        let mut shortest = vec![f64::INFINITY; mesh.n_vertices()];
        for &[a, b] in &topo.edges {
            let l = (x(a) - x(b)).length();
            for w in [a, b] {
                shortest[w as usize] = shortest[w as usize].min(l);
            }
        }
        // Quadric per patch, from that patch's faces at the vertex.
        let mut scratch = RingScratch::default();
        for (&v, faces) in &fan {
            let mut patches: Vec<u32> = faces.iter().map(|&(_, p)| p).collect();
            patches.sort_unstable();
            patches.dedup();
            for p in patches {
                let own: Vec<u32> = faces
                    .iter()
                    .filter(|&&(_, q)| q == p)
                    .map(|&(f, _)| f)
                    .collect();
                // One-sided two rings over the patch: the quadric's one ring leaves the cells
                // along a curved rim an O(h³) error the smooth vertices do not have, and a
                // rim vertex of a wall has too few rows across for the quadric at all (its
                // facets' normal then seeds the height function). Not next to thin cells
                // (as for the curve models below): a boundary layer's cells follow the
                // quadric and its inherited models, and fold under a more accurate wall.
                // At a seam the patch goes on across: the partner's facets of the patch
                // (those facing as v's do once carried over).
                let across =
                    partners
                        .get(v as usize)
                        .and_then(Option::as_ref)
                        .and_then(|&(w, t)| {
                            let theirs: Vec<u32> = fan
                                .get(&w)?
                                .iter()
                                .map(|&(f, _)| f)
                                .filter(|&f| facing_across(mesh, topo, &own, f, &t, cos_max))
                                .collect();
                            (!theirs.is_empty()).then_some((w, t, theirs))
                        });
                let fitted = match &across {
                    None => fan_model(mesh, topo, v, &own, cos_max),
                    Some((w, t, theirs)) => {
                        let (quads, nb) = fan_across(mesh, topo, (v, &own), (*w, theirs), t);
                        quad_fan_model(x(v), &quads, &nb, cos_max)
                    }
                };
                let Some((quadric, ell, normal)) = fitted else {
                    continue;
                };
                let seed = quadric.unwrap_or_else(|| flat(normal));
                let refined = (shortest[v as usize] >= RIM_Q2_MIN_ASPECT * ell)
                    .then(|| {
                        let mut ring = two_ring_from(
                            mesh,
                            topo,
                            &own,
                            fan_all,
                            smooth,
                            v,
                            cos_max,
                            &mut scratch,
                        );
                        if let Some((w, t, theirs)) = &across {
                            let more = two_ring_from(
                                mesh,
                                topo,
                                theirs,
                                fan_all,
                                smooth,
                                *w,
                                cos_max,
                                &mut scratch,
                            );
                            let mut pts: Vec<DVec3> = ring.iter().map(|&p| p.into()).collect();
                            pts.extend(more.iter().map(|&p| DVec3::from(t.apply(p))));
                            dedup_points(x(v), &mut pts);
                            ring = pts.into_iter().map(Into::into).collect();
                        }
                        refine_patch_model(mesh.coords[v as usize], &seed, &ring, ell)
                    })
                    .flatten();
                if let Some((m, higher)) = refined {
                    out.patch.insert((v, p), m);
                    out.patch_higher.insert((v, p), higher);
                } else if let Some(m) = quadric {
                    out.patch.insert((v, p), m);
                }
            }
        }
        // Curve models where a feature curve passes through (two feature edges), and their
        // refits over two neighbours each way. A curve ending on a seam goes on through the
        // partner's curve: its next two vertices there, carried over, are points numbered
        // from the vertex count on (`across`, read through `xa`).
        let along = features.curve_neighbours(topo);
        let nv = mesh.n_vertices() as u32;
        let mut across: Vec<DVec3> = Vec::new();
        let mut along_x = along.clone();
        for (&v, nbs) in &along {
            let Some((w, t)) = partners.get(v as usize).and_then(Option::as_ref) else {
                continue;
            };
            let (&[_], Some(&[c])) = (&nbs[..], along.get(w).map(|l| &l[..])) else {
                continue;
            };
            let id = nv + across.len() as u32;
            across.push(t.apply(mesh.coords[c as usize]).into());
            along_x.entry(v).or_default().push(id);
            let mut next = vec![v];
            if let Some(&[p, q]) = along.get(&c).map(|l| &l[..]) {
                let d = if p == *w { q } else { p };
                next.push(nv + across.len() as u32);
                across.push(t.apply(mesh.coords[d as usize]).into());
            }
            along_x.insert(id, next);
        }
        let xa = |u: u32| match u.checked_sub(nv) {
            None => x(u),
            Some(i) => across[i as usize],
        };
        let mut refits: HashMap<u32, (VertexModel, HigherModel)> = HashMap::new();
        for &v in along.keys() {
            let [a, b] = along_x[&v][..] else {
                continue;
            };
            let along_len = ((xa(a) - x(v)).length() + (xa(b) - x(v)).length()) / 2.0;
            if shortest[v as usize] < RIM_Q2_MIN_ASPECT * along_len {
                out.thin_rim.push(v);
            }
            if let Some(m) = curve_model(x(v), xa(a), xa(b)) {
                out.curve.insert(v, m);
                if let Some(h) = curve_higher(&along_x, v, [a, b], &m, &xa) {
                    refits.insert(v, h);
                }
            }
        }
        // Next to thin cells the refit replaces the parabola everywhere (`rim_higher`), else
        // on the feature edges only (on the rim alone it folds the thin cells). A coarse tip's
        // conic too: the thin cells at the ellipse tip of a one-layer extrusion then follow
        // the exact wall as in 2D (wall RMS 0.17× → 0.0074× the chords'; with the parabola,
        // 0.18× at the tip's edges).
        for (&v, &h) in &refits {
            let nbs = &along_x[&v];
            let along_len = nbs.iter().map(|&w| (xa(w) - x(v)).length()).sum::<f64>() / 2.0;
            if shortest[v as usize] >= RIM_Q2_MIN_ASPECT * along_len {
                out.curve_higher.insert(v, h);
            } else {
                out.curve.insert(v, h.0);
                out.rim_higher.insert(v, h.1);
                out.curve_higher.insert(v, h);
            }
        }
        // A patch one element wide across the curve (the wall of a one-layer extrusion) has
        // too few vertices at v for a quadric: the feature curve is its best model there. At a
        // thin rim the curve's refit also replaces the one-ring quadric of a patch that meets
        // the curve's plane at a right angle (an extruded wall, whose section the curve is):
        // the thin cells' other samples at v follow the refit.
        for (&v, faces) in &fan {
            let Some(m) = out.curve.get(&v).copied() else {
                continue;
            };
            let higher = out.rim_higher.get(&v).copied();
            let binormal = along_x.get(&v).and_then(|nbs| match nbs[..] {
                [a, b] => Some((xa(a) - x(v)).cross(xa(b) - x(v)).normalize_or_zero()),
                _ => None,
            });
            let binormal = binormal.filter(|b| *b != DVec3::ZERO);
            for &(_, p) in faces {
                let across =
                    |n: [f64; 3]| binormal.is_some_and(|b| b.dot(n.into()).abs() < RIM_WALL_SIN);
                match out.patch.get(&(v, p)) {
                    None => {}
                    Some(own) if higher.is_some() && across(own.normal) => {}
                    Some(_) => continue,
                }
                out.patch.insert((v, p), m);
                if let Some(h) = higher {
                    out.patch_higher.insert((v, p), h);
                }
            }
        }
        out.in_plane_models(mesh, topo, features, &along, decay, (share, links));
        out
    }

    /// On a rank of a distributed mesh whose sub-mesh has no feature while another rank's has
    /// some: the rank's part in the collective in-plane inheritance of [`FeatureModels::build`]
    /// (`nearest_shared` over `share`), with no rim vertex and no planar patch, so that every
    /// rank makes the same collective calls. Its vertices hand on no model, as its own build
    /// with no feature would find.
    pub fn join_shared_inheritance(mesh: &LinearMesh, decay: f64, share: &dyn InheritShare) {
        let paths = Paths {
            adj: &adjacency(mesh.n_vertices(), std::iter::empty()),
            seams: &(Vec::new(), Vec::new()),
            relaxable: &|_| false,
        };
        nearest_shared(mesh, &paths, &|_| None, decay, Some(share));
    }

    /// The 2D problem inside each planar patch: its rim vertices take their feature curve's
    /// model (in the plane) for the patch, and the patch's other vertices inherit the model of
    /// the nearest rim vertex (along the patch's edges) with weight 1 − d / (`decay` · ℓ), ℓ
    /// the rim's edge length there — as interior vertices of a 2D mesh inherit its boundary's.
    /// Those beyond reach keep a flat model. On a rank's part of a distributed mesh
    /// (`share`), the whole mesh's nearest rim vertices ([`nearest_shared`]); the paths run
    /// on across periodic seams along `links` (a patch cut by a seam is one patch).
    fn in_plane_models(
        &mut self,
        mesh: &LinearMesh,
        topo: &Topology,
        features: &Features,
        along: &HashMap<u32, Vec<u32>>,
        decay: f64,
        (share, links): (Option<&dyn InheritShare>, &[SeamLink]),
    ) {
        let x = |v: u32| DVec3::from(mesh.coords[v as usize]);
        let mut adj: Vec<[u32; 2]> = Vec::new();
        let mut plane_of: HashMap<u32, [f64; 3]> = HashMap::new();
        let mut rim: Vec<(u32, u32)> = Vec::new();
        for (i, &f) in topo.boundary_facets.iter().enumerate() {
            let p = features.facet_patch[i];
            let Some((n, _)) = features.planes[p as usize] else {
                continue;
            };
            let e = topo.facet_elements[f as usize][0] as usize;
            let side = topo.facet_sides[f as usize][0] as usize;
            for ed in crate::mesh::features::face_edges(topo, e, side) {
                adj.push(topo.edges[ed as usize]);
            }
            for &v in &topo.faces[f as usize] {
                if features.vertex_mask[v as usize] {
                    rim.push((v, p));
                } else {
                    plane_of.insert(v, n);
                }
            }
        }
        rim.sort_unstable();
        rim.dedup();
        // Rim vertices whose feature curve lies in the plane: the curve is the patch's boundary.
        let mut sources: HashMap<u32, VertexModel> = HashMap::new();
        for &(v, p) in &rim {
            let (Some(m), Some((n, _))) = (self.curve.get(&v), features.planes[p as usize]) else {
                continue;
            };
            if DVec3::from(m.normal).dot(n.into()).abs() > 1e-6 {
                continue;
            }
            self.patch.insert((v, p), *m);
            if let Some(h) = self.rim_higher.get(&v) {
                self.patch_higher.insert((v, p), *h);
            }
            sources.insert(v, *m);
        }
        let ell = |s: u32| {
            let nbs = &along[&s];
            nbs.iter().map(|&w| (x(w) - x(s)).length()).sum::<f64>() / nbs.len() as f64
        };
        let source = |v: usize| {
            let v32 = v as u32;
            Some(Source {
                model: *sources.get(&v32)?,
                higher: self.rim_higher.get(&v32).copied(),
                ell: ell(v32),
                order: share.map_or(v as u64, |s| s.order(v)),
                turned: false,
            })
        };
        let nv = mesh.n_vertices();
        let paths = Paths {
            adj: &adjacency(nv, adj.iter().copied()),
            seams: &seam_adjacency(nv, links),
            relaxable: &|w: usize| plane_of.contains_key(&(w as u32)),
        };
        let nearest = nearest_shared(mesh, &paths, &source, decay, share);
        for (&v, &n) in &plane_of {
            let model = match nearest.at[v as usize].filter(|n| !n.is_source) {
                Some(near) => {
                    let s = nearest.source(&near);
                    if let Some(h) = s.higher {
                        self.in_plane_higher.insert(v, h);
                    }
                    self.in_plane_scale.insert(v, s.ell);
                    VertexModel {
                        weight: 1.0 - near.dist / (decay * s.ell),
                        ..s.model
                    }
                }
                None => flat(n),
            };
            self.in_plane.insert(v, model);
        }
    }

    /// The model of feature vertex `k` for samples inside the mesh: its feature curve's, so
    /// the cells along a curved crease follow it as they follow a smooth boundary.
    pub(crate) fn interior_model(&self, k: u32) -> Option<&VertexModel> {
        self.curve.get(&k)
    }

    /// The model of vertex `k` for a sample on the boundary entity `at`.
    pub(crate) fn model(&self, k: u32, at: BoundaryEntity) -> Option<&VertexModel> {
        match self.patch_of(at) {
            None => self
                .curve_higher
                .get(&k)
                .map(|(m, _)| m)
                .or_else(|| self.curve.get(&k)),
            Some(p) => self.patch.get(&(k, p?)),
        }
    }

    /// The cubic and quartic terms of [`FeatureModels::model`] (`at` on the boundary) or of
    /// [`FeatureModels::interior_model`] (`None`), where it has them.
    pub(crate) fn higher(&self, k: u32, at: Option<BoundaryEntity>) -> Option<&HigherModel> {
        match at.map(|at| self.patch_of(at)) {
            None => self.rim_higher.get(&k),
            Some(None) => self.curve_higher.get(&k).map(|(_, h)| h),
            Some(Some(p)) => self.patch_higher.get(&(k, p?)),
        }
    }

    /// Per vertex of a mesh of `n` vertices, whether it lies on a thin rim (see
    /// `FeatureModels::thin_rim`; [`Features::thin_rim`]).
    pub fn thin_rim_mask(&self, n: usize) -> Vec<bool> {
        let mut mask = vec![false; n];
        for &v in &self.thin_rim {
            mask[v as usize] = true;
        }
        mask
    }

    /// `None` on a feature edge (curve models), else the patch of `at` if it has one.
    fn patch_of(&self, at: BoundaryEntity) -> Option<Option<u32>> {
        match at {
            BoundaryEntity::Edge(ed) if self.edge_mask[ed as usize] => None,
            BoundaryEntity::Edge(ed) => Some(self.edge_patch.get(&ed).copied()),
            BoundaryEntity::Facet(f) => Some(self.facet_patch.get(&f).copied()),
        }
    }
}

/// Whether facet `f` of the partner's side, carried over by `t`, faces as the facets `own`
/// do (its normal within acos(`cos_max`) of theirs): a facet of the same wall across a seam.
fn facing_across(
    mesh: &LinearMesh,
    topo: &Topology,
    own: &[u32],
    f: u32,
    t: &Rigid,
    cos_max: f64,
) -> bool {
    let normal = |q: [DVec3; 4]| (q[2] - q[0]).cross(q[3] - q[1]).normalize_or_zero();
    let x = |u: u32| DVec3::from(mesh.coords[u as usize]);
    let mine = own
        .iter()
        .map(|&g| normal(topo.faces[g as usize].map(x)))
        .sum::<DVec3>()
        .normalize_or_zero();
    let theirs =
        normal(topo.faces[f as usize].map(|u| DVec3::from(t.apply(mesh.coords[u as usize]))));
    mine.dot(theirs) >= cos_max
}

/// The curve model `m` of `v` (neighbours `nbs` along the feature curve) refitted as a height
/// function in the plane of v and its neighbours over up to two neighbours each way, circle
/// part first (exact on circular rims, see [`super::smooth`]); `None` keeps the parabola.
fn curve_higher(
    along: &HashMap<u32, Vec<u32>>,
    v: u32,
    nbs: [u32; 2],
    m: &VertexModel,
    x: &impl Fn(u32) -> DVec3,
) -> Option<(VertexModel, HigherModel)> {
    let n = DVec3::from(m.normal);
    if n == DVec3::ZERO {
        return None;
    }
    let mut pts = vec![x(nbs[0]).into(), x(nbs[1]).into()];
    for a in nbs {
        if let Some([p, q]) = along
            .get(&a)
            .and_then(|l| <[u32; 2]>::try_from(&l[..]).ok())
        {
            let next = if p == v { q } else { p };
            if next != v && !nbs.contains(&next) {
                pts.push(x(next).into());
            }
        }
    }
    let (ua, ub) = (x(nbs[0]) - x(v), x(nbs[1]) - x(v));
    let b = ua.cross(ub);
    let (lb, ell) = (b.length(), 0.5 * (ub - ua).length());
    if !(lb > 0.0 && ell > 0.0) {
        return None;
    }
    // Anisotropic: in a plane the conic is the circle, refitted until it converges.
    let how = Height {
        binormal: (b / lb).into(),
        anisotropic: true,
    };
    refine_model(2, x(v).into(), m, &pts, ell, how)
}

/// A patch meets a thin rim's plane at a right angle (`FeatureModels::rim_higher`) when its
/// normal's component along the plane's normal is below this sine (5°).
const RIM_WALL_SIN: f64 = 0.087;

/// A model without curvature (targets on the chords), of normal `n`.
fn flat(n: [f64; 3]) -> VertexModel {
    VertexModel {
        normal: n,
        h: [[0.0; 3]; 3],
        weight: 1.0,
    }
}

/// The parabola through x and its feature-curve neighbours a, b, as a model in their plane
/// (zero curvature when the three are collinear).
fn curve_model(x: DVec3, a: DVec3, b: DVec3) -> Option<VertexModel> {
    let (ua, ub) = (a - x, b - x);
    let d = ub - ua;
    let l = d.length();
    if l == 0.0 {
        return None;
    }
    let t = d / l;
    // In-plane normal: the part of ua + ub across the chord direction.
    let s = ua + ub;
    let off = s - t * s.dot(t);
    let lo = off.length();
    if lo <= 1e-12 * l {
        return Some(VertexModel {
            normal: [0.0; 3],
            h: [[0.0; 3]; 3],
            weight: 1.0,
        });
    }
    let n = off / lo;
    let to2 = |u: DVec3| [u.dot(t), u.dot(n), 0.0];
    let (n2, h2) = fit_parabola([0.0; 3], to2(ua), to2(ub))?;
    let back = |u: [f64; 3]| (t * u[0] + n * u[1]).into();
    // H = Σ_pq b_p h2_pq b_qᵀ summed entry by entry in this order (a DMat3 expression would
    // group the products differently and round differently).
    let basis = [t, n];
    let mut h = [[0.0; 3]; 3];
    for i in 0..3 {
        for j in 0..3 {
            for (p, bp) in basis.iter().enumerate() {
                for (q, bq) in basis.iter().enumerate() {
                    h[i][j] += bp[i] * h2[p][q] * bq[j];
                }
            }
        }
    }
    Some(VertexModel {
        normal: back(n2),
        h,
        weight: 1.0,
    })
}

/// Samples of element `e` that take the feature weight, as bits of the 3^d lattice index
/// (9z + 3y + x): its corners at feature vertices off thin rims ([`thin_rim_corners`]).
/// Midpoints of feature edges keep the midpoint weight: weighting them as strongly as the
/// vertices makes the quadratic spline trade vertex position for midpoint position where the
/// spacing along a feature changes, sliding feature vertices along their curve (measured on
/// the real meshes).
pub fn sample_mask(features: &Features, mesh: &LinearMesh, e: usize) -> u64 {
    let verts = mesh.element(e);
    let mut mask = 0u64;
    for (c, &v) in verts.iter().enumerate() {
        if features.vertex_mask[v as usize] && !features.on_thin_rim(v) {
            let p = HEX_VERTEX_PARAMS[c];
            let i = 2 * p[0] as usize + 6 * p[1] as usize + 18 * p[2] as usize;
            mask |= 1 << i;
        }
    }
    mask
}

/// Corners of element `e` (bit c for corner c) at thin-rim vertices ([`Features::thin_rim`]),
/// whose samples take [`thin_rim_weight`] instead of the feature weight.
pub fn thin_rim_corners(features: &Features, mesh: &LinearMesh, e: usize) -> u64 {
    let verts = mesh.element(e);
    let mut mask = 0u64;
    for (c, &v) in verts.iter().enumerate() {
        if features.on_thin_rim(v) {
            mask |= 1 << c;
        }
    }
    mask
}

/// The corner weight at a thin rim's vertices (a boundary layer's wall rim, where a feature
/// curve runs along cells much thinner than its edges): half the wall's boundary corner weight,
/// and never above the feature weight. The wall's targets along the rim are its targets at
/// mid-height, but a rim vertex is a corner of half as many of the wall's elements as a vertex
/// inside the wall, and a rim edge midpoint of one element: with the feature weight (100
/// against the midpoints' 1) the quadratic spline trades the rim's edge midpoints for its
/// vertices and bends the thin cells along the rim away from the wall (a Gmsh-made extruded
/// ellipse O-grid with 1e-5 wall cells: rim midpoints 7.6e-5 off the exact ellipse, the wall's
/// face centres at mid-height 1.8e-5); with the boundary corner weight 3.0e-5, with half of it
/// 1.8e-5, as at mid-height.
pub fn thin_rim_weight(w: &super::FitWeights) -> f64 {
    w.feature.min(0.5 * w.boundary_corner)
}

/// Project the boundary control points of `space` in `cps` onto the planes of the planar
/// patches (2D: the lines of the straight chains) of `features` they belong to (see module
/// docs). Returns how many moved.
pub fn project_onto_planes(
    space: &SplineSpace,
    topo: &Topology,
    features: &Features,
    cps: &mut [[f64; 3]],
) -> usize {
    if features.planes.iter().all(|p| p.is_none()) {
        return 0;
    }
    // Planar patches (2D: straight chains) of every boundary face, edge and vertex.
    let mut face_plane: HashMap<u32, u32> = HashMap::new();
    let mut edge_planes: HashMap<u32, Vec<u32>> = HashMap::new();
    let mut vertex_planes: HashMap<u32, Vec<u32>> = HashMap::new();
    for (i, &f) in topo.boundary_facets.iter().enumerate() {
        let p = features.facet_patch[i];
        if features.planes[p as usize].is_none() {
            continue;
        }
        if topo.dim == 2 {
            // The facet is the edge itself.
            edge_planes.entry(f).or_default().push(p);
        } else {
            face_plane.insert(f, p);
            let e = topo.facet_elements[f as usize][0] as usize;
            let side = topo.facet_sides[f as usize][0] as usize;
            for ed in crate::mesh::features::face_edges(topo, e, side) {
                edge_planes.entry(ed).or_default().push(p);
            }
        }
        for &v in topo.facet_vertices(f as usize) {
            vertex_planes.entry(v).or_default().push(p);
        }
    }
    let mut moved = 0;
    for (c, key) in cps.iter_mut().zip(&space.control_point_keys) {
        use ControlPoint::*;
        let mut ps: Vec<u32> = match *key {
            BFace(f) | Q2Face(f) => face_plane.get(&f).map(|&p| vec![p]).unwrap_or_default(),
            BEdge(ed) | Q2Edge(ed) => edge_planes.get(&ed).cloned().unwrap_or_default(),
            BVertex(v) | Q2Vertex(v) => vertex_planes.get(&v).cloned().unwrap_or_default(),
            Cell(_) | Q2Centre(_) => Vec::new(),
        };
        ps.sort_unstable();
        ps.dedup();
        if ps.is_empty() {
            continue;
        }
        let planes: Vec<([f64; 3], f64)> = ps
            .iter()
            .map(|&p| features.planes[p as usize].expect("planar"))
            .collect();
        // Planes that coincide (two straight chains on one line, split by a tag change) leave
        // the intersection undefined: one of them is the constraint.
        let p = DVec3::from(*c);
        if let Some(x) = project(p, &planes).or_else(|| project(p, &planes[..1])) {
            moved += 1;
            *c = x.into();
        }
    }
    moved
}

/// The nearest point to x on the intersection of up to three planes n·y = d (None when their
/// normals are dependent, e.g. more than three planes or parallel ones).
fn project(x: DVec3, planes: &[([f64; 3], f64)]) -> Option<DVec3> {
    let m = planes.len();
    if m > 3 {
        return None;
    }
    // y = x + Nᵀ λ with (N Nᵀ) λ = d − N x.
    let n = |i: usize| DVec3::from(planes[i].0);
    let mut g = [[0.0; 3]; 3];
    let mut r = [0.0; 3];
    for i in 0..m {
        for j in 0..m {
            g[i][j] = n(i).dot(n(j));
        }
        r[i] = planes[i].1 - n(i).dot(x);
    }
    let lambda = solve_small(g, r, m)?;
    let mut y = x;
    for (i, l) in lambda.iter().enumerate().take(m) {
        y += n(i) * *l;
    }
    Some(y)
}

/// Solve the leading m×m block of g λ = r by elimination; None when near singular.
fn solve_small(mut g: [[f64; 3]; 3], mut r: [f64; 3], m: usize) -> Option<[f64; 3]> {
    for c in 0..m {
        let p = (c..m).max_by(|&i, &j| g[i][c].abs().total_cmp(&g[j][c].abs()))?;
        if g[p][c].abs() < 1e-8 {
            return None;
        }
        g.swap(c, p);
        r.swap(c, p);
        for i in c + 1..m {
            let f = g[i][c] / g[c][c];
            for k in c..m {
                g[i][k] -= f * g[c][k];
            }
            r[i] -= f * r[c];
        }
    }
    let mut x = [0.0; 3];
    for i in (0..m).rev() {
        let mut s = r[i];
        for k in i + 1..m {
            s -= g[i][k] * x[k];
        }
        x[i] = s / g[i][i];
    }
    Some(x)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A feature curve on a circle: the corrected chord midpoint is much closer to the circle
    /// than the chord's; a straight feature line gets no correction.
    #[test]
    fn curve_model_follows_a_circle_in_space() {
        // Circle of radius 2 in the tilted plane spanned by e1 and (0, 1, 1)/√2.
        let s = std::f64::consts::FRAC_1_SQRT_2;
        let c = |t: f64| DVec3::new(2.0 * t.cos(), 2.0 * t.sin() * s, 2.0 * t.sin() * s);
        let (a, x, b) = (c(0.0), c(0.2), c(0.45));
        let m = curve_model(x, a, b).unwrap();
        let p = 0.5 * (x + b);
        let q = p + DVec3::from(m.correction(p.into(), &[x.into(), b.into()], 0.5));
        let (ep, eq) = ((p.length() - 2.0).abs(), (q.length() - 2.0).abs());
        assert!(eq < 0.05 * ep, "chord {ep}, corrected {eq}");
        let line = curve_model(DVec3::ONE, DVec3::ZERO, DVec3::splat(3.0)).unwrap();
        let p = [2.0; 3];
        assert_eq!(line.correction(p, &[[1.0; 3], [3.0; 3]], 0.5), [0.0; 3]);
    }

    /// Projection onto one plane, two planes (their line) and three (their point).
    #[test]
    fn projection_onto_plane_intersections() {
        let x = DVec3::new(1.0, 2.0, 3.0);
        let px = ([1.0, 0.0, 0.0], 0.0);
        let py = ([0.0, 1.0, 0.0], 0.5);
        let pz = ([0.0, 0.0, 1.0], -1.0);
        assert_eq!(project(x, &[px]).unwrap(), DVec3::from([0.0, 2.0, 3.0]));
        assert_eq!(project(x, &[px, py]).unwrap(), DVec3::from([0.0, 0.5, 3.0]));
        assert_eq!(
            project(x, &[px, py, pz]).unwrap(),
            DVec3::from([0.0, 0.5, -1.0])
        );
        assert!(project(x, &[px, px]).is_none());
    }
    /// Along a circular feature curve (22.5° per edge, in a tilted plane) the refitted curve
    /// model's chord-midpoint target is on the circle to rounding; the parabola's is not.
    #[test]
    fn curve_height_function_is_exact_on_circles() {
        let s = std::f64::consts::FRAC_1_SQRT_2;
        let dt = std::f64::consts::PI / 8.0;
        let c = |i: u32| {
            let t = i as f64 * dt;
            DVec3::new(2.0 * t.cos(), 2.0 * t.sin() * s, 2.0 * t.sin() * s)
        };
        let mut along: HashMap<u32, Vec<u32>> = HashMap::new();
        for i in 0..5u32 {
            along.insert(
                i,
                [i.checked_sub(1), (i < 4).then_some(i + 1)]
                    .into_iter()
                    .flatten()
                    .collect(),
            );
        }
        let parabola = curve_model(c(2), c(1), c(3)).unwrap();
        let (m, hm) = curve_higher(&along, 2, [1, 3], &parabola, &c).unwrap();
        let p = 0.5 * (c(2) + c(3));
        let xs = [c(2).into(), c(3).into()];
        let before = p + DVec3::from(parabola.correction(p.into(), &xs, 0.5));
        let after = p
            + DVec3::from(m.correction(p.into(), &xs, 0.5))
            + hm.correction(p.into(), &xs, 0.5) * DVec3::from(m.normal);
        let (e0, e1) = ((before.length() - 2.0).abs(), (after.length() - 2.0).abs());
        assert!(e1 < 1e-12, "height function {e1:e}");
        assert!(e0 > 1e-5, "parabola {e0:e}");
    }
}
