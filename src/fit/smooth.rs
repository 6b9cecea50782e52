//! Midpoint targets from a local reconstruction of the smooth boundary (`--fit smooth`).
//!
//! With the paper's targets, the edge/face midpoints of the boundary lie on the straight chords
//! of the input, so the fitted boundary keeps a fixed fraction of the linear mesh's O(h²)
//! error. Here every smooth boundary vertex v carries a local second-order model of the
//! boundary: a unit normal n_v and the quadratic part of a height function over its tangent
//! plane, stored as the symmetric tensor H_v = T Q Tᵀ (T the tangent frame, so H_v n_v = 0):
//! * 2D: the parabola η = c₁ξ + c₂ξ² in the frame of v through its two boundary neighbours,
//!   H_v = c₂ t tᵀ; the frame is re-tilted to the parabola's tangent and the fit repeated;
//! * 3D: the least-squares quadric η = aξ² + bξζ + cζ² + dξ + eζ over the vertices of the
//!   boundary faces around v, with the normal re-tilted by (d, e) and the fit repeated.
//!
//! A sample point p = Σ_j φ_j x_j of an entity (edge midpoint, face or cell centre, φ_j its
//! multilinear weights) is moved by the models of the entity's vertices:
//!
//!   Δ(p) = Σ_k ω_k γ_k c_k(p),   c_k(p) = −(Σ_j φ_j y_jᵀ H_k y_j) n_k,   y_j = x_j − p,
//!
//! which is exactly "surface of model k above p minus the multilinear interpolation of the
//! surface at the vertices": the linear part of every model cancels, so c_k depends only on
//! the curvature, not on where the entity sits along the normal. On a boundary entity the
//! weights ω_k = φ_k are renormalised over the vertices that have a model (γ = 1); a vertex at
//! a sharp feature (a facet normal more than `feature_angle_deg` from the vertex normal, or a
//! non-manifold fan) has none, so targets there stay on the chords. Points on a smooth
//! boundary are reproduced to O(h³) (O(h⁴) where the spacing is locally uniform), so the
//! fitted quadratic boundary converges at third order instead of second — provided the space
//! can follow the boundary grid: a C¹ spline element cannot follow grid lines that kink within
//! the surface (a cubed sphere's block arcs, order ≈ 1.6 there), so the pipeline makes the
//! elements at such kinks Q2 ([`crate::spline::kinks`], `kink_angle_deg`).
//!
//! Interior vertices within `decay` × (local boundary edge length) of the boundary, measured
//! along mesh edges, inherit the model of their nearest smooth boundary vertex with weight
//! γ = 1 − distance / (decay · length). Interior midpoints near the boundary therefore follow
//! the boundary's correction: a thin boundary-layer cell is moved as a whole instead of having
//! its boundary side pushed through its inner side, while isotropic cells see the correction
//! only on their boundary side.
//!
//! **Reach.** A model is a reconstruction over its source's two rings (about 2ℓ), and its
//! height function grows as (ξ/ℓ)⁴ beyond, so a sample takes no correction from a model when
//! a corner of its entity lies more than [`MODEL_REACH`] × ℓ (ℓ the source's boundary edge
//! length) from it along the model's curved directions. Only entities far larger than the
//! wall's cells next to inheriting vertices are concerned: the single outer cell of an O-grid
//! whose whole boundary layer is thinner than the decay distance (first cell 10⁻⁶, growth
//! 1.05: 47 cells within 2·10⁻⁴ of the wall, then one cell to the far field). There the
//! wall's models, evaluated hundreds of ℓ away, folded the target map in most outer cells,
//! and the certified blend, holding them back to the straight elevation, took every thin cell
//! below them and the wall back to the chords too (a thin cell cannot have one side curved
//! and the other straight).
//!
//! **Two-ring height functions.** The one-ring quadric leaves an error of order h⁴ with a large
//! constant (on a circle of 14 segments, 1.8 % of the chord's sagitta) and of order h³ where
//! the ring is irregular, which is what Q2 elements at irregular vertices interpolate. Each
//! smooth vertex's model is therefore refitted over the boundary vertices within two rings
//! (2D: two neighbours each way along the boundary; 3D: over boundary faces, the second ring
//! reached only through smooth vertices, so never across a feature) as a height function
//!
//!   η(ξ) = s_κ(ξ) + Σ c_m m(ξ),   s_κ the height of the circle/sphere of curvature κ,
//!
//! with the monomials m of degree 1–4 (2D: through up to four points; 3D: least squares over at
//! least 20 points, degree 1–3 over at least 12), κ updated from the isotropic part of the
//! fitted quadratic and the frame re-tilted by the linear terms, as for the quadric. The model
//! is then exact on circles and spheres at any resolution and accurate to higher order
//! elsewhere; its quadratic part is the vertex's H and normal, the rest (`HigherModel`) adds
//! g(ξ_p) − Σ_j φ_j g(ξ_j) along the normal. Too few points, points that are not a graph over
//! the tangent plane, or a singular system keep the one-ring quadric. A plane curve whose ring
//! turns from the vertex's tangent by more than 15° (an ellipse's coarse tip) takes the conic
//! through the vertex and its four ring points instead (`higher::conic_fit`): exact on circles
//! and ellipses, and defined where the ring folds back past the tip.
//!
//! **One-sided rings.** Next to a feature the ring stops at the feature's vertices (points of
//! this side's surface). There the circle/sphere s_κ is replaced by the conic of the fitted
//! curvature form (`higher::Height::ONE_SIDED`): the sphere of the mean curvature leaves
//! quartic terms on a cylinder that a one-sided ring cannot cancel (the targets along an
//! O-grid cylinder's rims were 12× Gmsh-with-CAD's distance; now within 1.1×). The feature
//! vertices' own patch and curve models are refitted the same way
//! ([`super::features::FeatureModels`]).
//!
//! **Coarse surfaces.** Where the normals of two smooth boundary vertices sharing a facet
//! turn by more than 30° (a torus of eight cells around the tube), the two rings reach a
//! quarter turn or more and no polynomial model follows the surface there. The 3D boundary
//! edge midpoints and face centres at such vertices take circular arcs on the vertex normals
//! instead (`arcs`; regular coarse vertices take their normal from the conics through five
//! points of their grid lines, or the circles through three; at and next to a periodic seam the
//! fan and the grid lines go on over the other side, carried across by the seam's map). An interior sample whose vertices inherited their models from the corners of
//! such a boundary edge or face (after dropping its directions across the layers, along which
//! the sources do not change) takes that entity's arc, times the mean inherited weight: the
//! models and the arcs differ there by far more than a boundary-layer cell's height, so a thin
//! cell with its wall side on the arcs and its inner side on the models folds. Other interior
//! samples keep the models.
//!
//! With detected sharp features ([`SmoothTargets::build_with_features`]) the vertices on
//! features take their models per patch and along feature curves instead
//! ([`super::features::FeatureModels`]), so no model averages across a feature; samples inside
//! the mesh use a feature vertex's curve model. The vertices of planar patches (2D: straight
//! chains) take in-plane models from the patch's rim instead of their flat fan model, and in
//! 3D are no sources for the interior vertices.

mod arcs;
mod higher;
mod one_ring;

use super::features::{BoundaryEntity, FeatureModels};
use crate::math::Lattice;
use crate::math::bernstein::net_len;
use crate::math::linalg::DVec3;
use crate::math::reference::{HEX_EDGES, HEX_VERTEX_PARAMS};
use crate::mesh::features::Features;
use crate::mesh::periodic::Rigid;
use crate::mesh::topology::NONE;
use crate::mesh::{LinearMesh, Topology};
use higher::two_ring;
pub(super) use higher::{
    Height, HigherModel, RingScratch, refine_model, refine_patch_model, two_ring_from,
};
pub(super) use one_ring::{fan_model, fit_parabola, quad_fan_model};
use rayon::prelude::*;
use std::cmp::Reverse;
use std::collections::{BinaryHeap, HashMap};

/// A seam link ([`crate::spline::seam::SeamView::seam_links`]): a vertex, the other side's
/// vertex on the same glued vertex, and the map carrying that side onto the vertex's.
pub type SeamLink = (u32, u32, Rigid);

/// The walls' partners across periodic seams and the seams' links
/// ([`SmoothTargets::build_shared`]'s `partners` and `links`).
pub type SeamSides<'a> = (&'a [Option<(u32, Rigid)>], &'a [SeamLink]);

/// Parameters of the smooth-boundary reconstruction.
#[deny(missing_docs)]
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct SmoothParams {
    /// A boundary vertex is a sharp feature (no model, chord targets) when a boundary facet at
    /// it has its normal more than this angle (degrees) away from the vertex normal.
    pub feature_angle_deg: f64,
    /// Interior vertices inherit the boundary model with weight 1 − d / (decay · ℓ), d the
    /// distance along mesh edges to the boundary vertex, ℓ its boundary edge length; 0 keeps
    /// all interior targets on the chords.
    pub decay: f64,
    /// Elements touching a vertex where a boundary grid line kinks (geodesic turning jumping
    /// against the line's neighbours by more than the vertex's normal turning, clamped to
    /// [1°, this angle]; [`crate::spline::kinks`]) become constrained Q2 elements; 180 or
    /// more turns the detection off.
    pub kink_angle_deg: f64,
    /// Elements touching a regular interior vertex where an interior grid line turns by more
    /// than this angle ([`crate::spline::kinks::interior_kink_elements`]) become Q2 in the
    /// spline passes' redo where the pass kept holds back more than a tenth
    /// (`pipeline::passes`); 180 or more (the default) turns the detection off.
    pub interior_kink_angle_deg: f64,
}

impl Default for SmoothParams {
    fn default() -> Self {
        SmoothParams {
            feature_angle_deg: 30.0,
            decay: 1.0,
            kink_angle_deg: 10.0,
            // Opt-in (`--interior-kink-angle`): see `crate::spline::kinks::INTERIOR_KINK_ANGLE_DEG`.
            interior_kink_angle_deg: 180.0,
        }
    }
}

/// The local second-order boundary model carried by a vertex.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct VertexModel {
    /// Unit normal of the model.
    pub normal: [f64; 3],
    /// Curvature tensor H = T Q Tᵀ (symmetric; H · normal = 0).
    pub h: [[f64; 3]; 3],
    /// 1 on the boundary; the decayed weight γ on interior vertices.
    pub weight: f64,
}

impl VertexModel {
    /// The model's displacement c(p) of the point p = Σ φ_j x_j of an entity (see module docs).
    pub(crate) fn correction(&self, p: [f64; 3], xs: &[[f64; 3]], phi: f64) -> [f64; 3] {
        let p = DVec3::from(p);
        let h = self.h.map(DVec3::from);
        let mut s = 0.0;
        for x in xs {
            let y = DVec3::from(*x) - p;
            let hy = DVec3::new(h[0].dot(y), h[1].dot(y), h[2].dot(y));
            s += phi * y.dot(hy);
        }
        (-s * DVec3::from(self.normal)).into()
    }

    /// The model seen through the rigid map `t` (a periodic seam's): normal R n, H' = R H Rᵀ.
    pub(crate) fn carried(&self, t: &Rigid) -> VertexModel {
        let r = t.rotation.map(DVec3::from);
        let rot = |x: [f64; 3]| [r[0].dot(x.into()), r[1].dot(x.into()), r[2].dot(x.into())];
        // R H Rᵀ: the rows of H Rᵀ are R applied to the rows of H (H symmetric), then R on
        // its columns.
        let hrt = self.h.map(rot);
        let h = std::array::from_fn(|i| {
            std::array::from_fn(|j| (0..3).map(|k| t.rotation[i][k] * hrt[k][j]).sum())
        });
        VertexModel {
            normal: rot(self.normal),
            h,
            ..*self
        }
    }

    /// How far the points `xs` reach from `p` along the model's curved directions:
    /// max √(|yᵀ H y| / ‖H‖), y = x − p (‖·‖ Frobenius; 0 for a flat model). Offsets along
    /// which the model does not bend (a cylinder's axis, an extrusion's span under a curve
    /// model) do not count: the model is exact along them.
    fn curved_extent(&self, p: [f64; 3], xs: &[[f64; 3]]) -> f64 {
        let h = self.h.map(DVec3::from);
        let norm = h.iter().map(|r| r.length_squared()).sum::<f64>().sqrt();
        if norm == 0.0 {
            return 0.0;
        }
        xs.iter()
            .map(|x| {
                let y = DVec3::from(*x) - DVec3::from(p);
                (y.dot(DVec3::new(h[0].dot(y), h[1].dot(y), h[2].dot(y)))
                    .abs()
                    / norm)
                    .sqrt()
            })
            .fold(0.0, f64::max)
    }
}

/// Per-vertex boundary models of a mesh, and the sample-point corrections they give.
#[derive(Clone, Debug, Default)]
pub struct SmoothTargets {
    dim: usize,
    models: Vec<Option<VertexModel>>,
    /// Boundary vertices with a model.
    pub smooth_vertices: usize,
    /// Boundary vertices without one (sharp features, non-manifold or degenerate fans).
    pub feature_vertices: usize,
    /// Interior vertices with an inherited model of positive weight.
    pub blended_vertices: usize,
    /// Models of the feature vertices per patch and curve, with features.
    feature_models: Option<FeatureModels>,
    /// The cubic and quartic terms of a smooth vertex's height function over two rings
    /// ([`HigherModel`]); interior vertices share their source's.
    higher: Vec<Option<HigherModel>>,
    /// 3D, with at least one coarse vertex ([`arcs`]), else empty: the normal of each smooth
    /// boundary vertex, whether it is coarse, and a coarse vertex's grid-line conics.
    arc_normals: Vec<Option<ArcVertex>>,
    /// With arc normals: the smooth boundary vertex each vertex takes its model from (itself
    /// on the boundary, the nearest one for an interior vertex that inherited one), else
    /// `NONE`; empty without arc normals.
    sources: Vec<u32>,
    /// Per vertex with a model: the boundary edge length ℓ of the vertex the model was fitted
    /// at (itself, its source, or a planar patch's rim vertex); ∞ where unknown (flat models).
    /// An entity reaching farther than [`MODEL_REACH`] × ℓ from a sample takes no correction
    /// from that model there.
    scale: Vec<f64>,
}

/// How far, in boundary edge lengths ℓ of its source, a vertex model is evaluated (see the
/// module docs): an entity whose corners lie farther than this from one of its samples along
/// the model's curved directions (`VertexModel::curved_extent`) takes no correction from
/// the model at that sample. On the real meshes of the repository no entity reaches 2ℓ; the
/// outer cells of the generated O- and C-grids whose boundary layer lies within the decay
/// distance reach 250–830ℓ.
pub const MODEL_REACH: f64 = 4.0;

impl SmoothTargets {
    /// Reconstruct the boundary models of `mesh` (quads or hexes) with topology `topo`.
    pub fn build(mesh: &LinearMesh, topo: &Topology, params: &SmoothParams) -> SmoothTargets {
        Self::build_with_features(mesh, topo, params, None)
    }

    /// [`SmoothTargets::build`] where the vertices on `features` take per-patch and curve
    /// models instead of one model each.
    pub fn build_with_features(
        mesh: &LinearMesh,
        topo: &Topology,
        params: &SmoothParams,
        features: Option<&Features>,
    ) -> SmoothTargets {
        Self::build_shared(mesh, topo, params, features, None, &[], &[])
    }

    /// [`SmoothTargets::build_with_features`] on a rank's part of a mesh distributed over
    /// ranks (`share`, see [`InheritShare`]; `None`: the whole mesh), whose vertices of the
    /// rank's own elements inherit the whole mesh's interior models, and with walls that go
    /// on across periodic seams: `partners[v]` (empty: none) is, at a wall vertex on a seam,
    /// the other side's vertex on the same glued vertex and the rigid map carrying that side
    /// onto this one ([`crate::spline::seam::SeamView::wall_partners`]). The models at and
    /// next to such a vertex are fitted over the wall on both sides, the other side's points
    /// carried over by the map (2D: along the boundary curve; 3D: the vertex's fan and two
    /// rings, its neighbours' rings through it, and where a rim meets the seam the rim's
    /// curve and patch models, `FeatureModels::build`), so they are
    /// two-sided as in the interior of the wall, and the models of the two sides' seam
    /// vertices are images of each other. `links` (empty: none) are the seams' vertex pairs
    /// ([`crate::spline::seam::SeamView::seam_links`]): the interior vertices inherit their
    /// models along the mesh edges and across the seams through them, a model reached across
    /// carried by the seam's map, so a vertex next to a seam takes the nearest wall vertex on
    /// either side, and the two sides' vertices on a seam take images of the same model. On a
    /// coarse wall (the module docs' coarse surfaces) the fans and grid lines that give the
    /// arcs' normals go on across the seams through `links` too (a seam corner's three glued
    /// vertices included), so the arcs at and next to a seam are those of the glued wall.
    #[allow(clippy::too_many_arguments)]
    pub fn build_shared(
        mesh: &LinearMesh,
        topo: &Topology,
        params: &SmoothParams,
        features: Option<&Features>,
        share: Option<&dyn InheritShare>,
        partners: &[Option<(u32, Rigid)>],
        links: &[(u32, u32, Rigid)],
    ) -> SmoothTargets {
        let nv = mesh.n_vertices();
        let cos_max = params.feature_angle_deg.to_radians().cos();
        // Boundary fans: facets at each boundary vertex.
        let mut fan: Vec<Vec<u32>> = vec![Vec::new(); nv];
        for &f in &topo.boundary_facets {
            for &v in topo.facet_vertices(f as usize) {
                fan[v as usize].push(f);
            }
        }
        let seam = Seam {
            dim: mesh.dim,
            fan: &fan,
            partners,
            links,
        };
        let (mut models, ell) = one_ring_models(mesh, topo, params, features, &fan, &seam);
        let mut higher = two_ring_models(mesh, topo, &fan, &mut models, &ell, cos_max, &seam);
        let arc_normals = match share {
            Some(s) if mesh.dim == 3 => shared_coarse_normals(mesh, topo, &fan, &models, &seam, s),
            _ => coarse_normals(mesh, topo, &fan, &models, &seam),
        };
        let smooth_vertices = models.iter().filter(|m| m.is_some()).count();
        let feature_vertices =
            topo.vertex_on_boundary.iter().filter(|&&b| b).count() - smooth_vertices;
        // In 3D the feature models' in-plane inheritance is collective over a share: a rank
        // whose sub-mesh has no feature (a smooth shape whose ghost rings hold all of it)
        // joins it while another rank's has some (its cut fringe), or the ranks' collective
        // calls would part and wait for each other for ever.
        let any_features = match share {
            Some(s) if mesh.dim == 3 => s.any(features.is_some()),
            _ => features.is_some(),
        };
        let feature_models = features.map(|f| {
            FeatureModels::build(
                mesh,
                topo,
                f,
                cos_max,
                params.decay,
                &fan,
                &models,
                share,
                (partners, links),
            )
        });
        if let (None, true, Some(s)) = (&feature_models, any_features, share) {
            FeatureModels::join_shared_inheritance(mesh, params.decay, s);
        }
        // A 3D planar patch is its own 2D problem (its vertices take in-plane models below):
        // the cells next to it inherit from the curved boundary, not from the plane.
        let in_plane_3d = |v: usize| {
            mesh.dim == 3
                && feature_models
                    .as_ref()
                    .is_some_and(|f| f.in_plane.contains_key(&(v as u32)))
        };

        let inherited = if params.decay > 0.0 {
            inherit_interior(
                mesh,
                topo,
                params.decay,
                &ell,
                &in_plane_3d,
                &mut models,
                &mut higher,
                (share, links),
            )
        } else {
            Inherited::default()
        };
        let (blended_vertices, sources) = (inherited.vertices, inherited.sources);
        // A model's scale is its source's boundary edge length (every model so far is a
        // boundary vertex's own or inherited from its source).
        let mut scale: Vec<f64> = (0..nv)
            .into_par_iter()
            .with_min_len(1024)
            .map(|v| match (models[v], inherited.scale.get(v)) {
                (None, _) => f64::INFINITY,
                (Some(_), Some(&l)) if !l.is_nan() => l,
                (Some(_), _) => ell[v],
            })
            .collect();
        if let Some(f) = &feature_models {
            for (&v, m) in &f.in_plane {
                models[v as usize] = Some(*m);
                scale[v as usize] = f.in_plane_scale.get(&v).copied().unwrap_or(f64::INFINITY);
                // The height function was fitted over the plane, not along the in-plane curve;
                // a thin rim's curve refit comes with its own.
                higher[v as usize] = f.in_plane_higher.get(&v).copied();
            }
        }
        SmoothTargets {
            dim: mesh.dim,
            models,
            smooth_vertices,
            feature_vertices,
            blended_vertices,
            feature_models,
            higher,
            sources: if arc_normals.is_empty() {
                Vec::new()
            } else {
                sources
            },
            arc_normals,
            scale,
        }
    }

    /// Per vertex, whether it lies on a thin rim (`features::FeatureModels`); empty without
    /// features. The fit weighs the corners there by [`super::features::thin_rim_weight`]
    /// ([`crate::mesh::features::Features::thin_rim`]).
    pub fn thin_rim_mask(&self) -> Vec<bool> {
        self.feature_models
            .as_ref()
            .map_or_else(Vec::new, |f| f.thin_rim_mask(self.models.len()))
    }

    /// The model of vertex `v`, if it has one.
    pub fn vertex_model(&self, v: usize) -> Option<&VertexModel> {
        self.models[v].as_ref()
    }

    /// Displacements of the 3^d sample targets of element `e` from the multilinear points
    /// (index 9z + 3y + x of the lattice {0, ½, 1}^d; zero at corners).
    pub fn element_corrections(&self, mesh: &LinearMesh, topo: &Topology, e: usize) -> Lattice {
        let lattice = super::rhs::multilinear_lattice(self.dim, &mesh.element_coords(e));
        self.corrections_at(mesh, topo, e, &lattice)
    }

    /// [`SmoothTargets::element_corrections`] given the element's multilinear map at the
    /// lattice (`lattice[i]` the multilinear point of sample i).
    pub(crate) fn corrections_at(
        &self,
        mesh: &LinearMesh,
        topo: &Topology,
        e: usize,
        lattice: &Lattice,
    ) -> Lattice {
        let dim = self.dim;
        let n = net_len(dim);
        let verts = mesh.element(e);
        let mut out = [[0.0; 3]; 27];
        // Without a vertex model, only feature models at boundary entities (whose vertices are
        // boundary vertices) can move a sample.
        let unmoved = |v: usize| {
            self.models[v].is_none()
                && (self.feature_models.is_none() || !topo.vertex_on_boundary[v])
        };
        if verts.iter().all(|&v| unmoved(v as usize)) {
            return out;
        }
        let x = mesh.element_coords(e);
        let (mut xs, mut ks, mut cs) = ([[0.0; 3]; 8], [0usize; 8], [0usize; 8]);
        for (i, slot) in out.iter_mut().enumerate().take(n) {
            let l = [i % 3, (i / 3) % 3, i / 9];
            let m = (0..dim).filter(|&k| l[k] == 1).count();
            if m == 0 {
                continue;
            }
            let mut len = 0;
            for (c, pc) in HEX_VERTEX_PARAMS.iter().enumerate().take(1 << dim) {
                if (0..dim).all(|k| l[k] == 1 || 2 * pc[k] as usize == l[k]) {
                    (xs[len], ks[len], cs[len]) = (x[c], verts[c] as usize, c);
                    len += 1;
                }
            }
            let (xs, ks) = (&xs[..len], &ks[..len]);
            if ks.iter().all(|&k| unmoved(k)) {
                continue;
            }
            let at = if m < dim {
                self.boundary_entity(topo, e, l)
            } else {
                None
            };
            let on_boundary = at.is_some();
            let p = lattice[i];
            let phi = 1.0 / len as f64;
            let mut delta = DVec3::ZERO;
            let mut wsum = 0.0;
            for &k in ks {
                // Beyond the model's reach it would fold the entity (see `MODEL_REACH`).
                if let Some(m) = &self.models[k]
                    && m.curved_extent(p, xs) > MODEL_REACH * self.scale[k]
                {
                    continue;
                }
                let higher = match self.models[k] {
                    Some(_) => self.higher.get(k).copied().flatten(),
                    None => self
                        .feature_models
                        .as_ref()
                        .and_then(|f| f.higher(k as u32, at).copied()),
                };
                let model = self.models[k].as_ref().or_else(|| {
                    let f = self.feature_models.as_ref()?;
                    match at {
                        Some(at) => f.model(k as u32, at),
                        None => f.interior_model(k as u32),
                    }
                });
                if let Some(model) = model {
                    let mut c = DVec3::from(model.correction(p, xs, phi));
                    if let Some(hm) = higher {
                        let g = hm.correction(p, xs, phi);
                        c += g * DVec3::from(model.normal);
                    }
                    let w = phi * model.weight;
                    delta += w * c;
                    wsum += phi;
                }
            }
            if on_boundary && wsum > 0.0 {
                delta /= wsum;
            }
            if !self.arc_normals.is_empty() {
                let arc = if on_boundary {
                    self.arc_target(xs, ks, &cs[..len], l)
                } else {
                    self.inherited_arc(topo, mesh, ks, &cs[..len], l)
                };
                if let Some(d) = arc {
                    delta = d;
                }
            }
            *slot = delta.into();
        }
        out
    }

    /// The target displacement from the vertex normals ([`arcs`]) of the 3D boundary edge
    /// midpoint or face centre at lattice point `l` with corners `xs` (vertices `ks`, element
    /// corners `cs`), when one of them is coarse and all are smooth boundary vertices.
    fn arc_target(
        &self,
        xs: &[[f64; 3]],
        ks: &[usize],
        cs: &[usize],
        l: [usize; 3],
    ) -> Option<DVec3> {
        let normals: Vec<ArcVertex> = ks
            .iter()
            .map(|&k| self.arc_normals[k])
            .collect::<Option<_>>()?;
        if !normals.iter().any(|a| a.coarse) {
            return None;
        }
        let (x, n) = (
            |i: usize| DVec3::from(xs[i]),
            |i: usize| DVec3::from(normals[i].normal),
        );
        let edge =
            |i: usize, j: usize| ArcVertex::edge_target([&normals[i], &normals[j]], [x(i), x(j)]);
        match ks.len() {
            2 => edge(0, 1),
            4 => {
                // Corners in the face's lattice order: index p₁ + 2 p₂ of their parameters
                // along the face's two free directions.
                let free: Vec<usize> = (0..3).filter(|&k| l[k] == 1).collect();
                let (mut xf, mut nf, mut at) = ([DVec3::ZERO; 4], [DVec3::ZERO; 4], [0; 4]);
                for (i, &c) in cs.iter().enumerate() {
                    let p = HEX_VERTEX_PARAMS[c];
                    let j = p[free[0]] as usize + 2 * p[free[1]] as usize;
                    (xf[j], nf[j], at[j]) = (x(i), n(i), i);
                }
                arcs::face_arc(&xf, &nf, |i, j| edge(at[i], at[j]))
            }
            _ => None,
        }
    }

    /// The target displacement of an interior sample (lattice point `l`, element corners `cs`
    /// at vertices `ks`) whose vertices all inherited their models from smooth boundary
    /// vertices ([`inherit_interior`]) that form a boundary edge or face with a coarse vertex:
    /// that entity's [`arcs`] target, times the mean inherited weight γ. A boundary-layer
    /// cell is then moved as a whole, its inner side along its wall side's arcs; the models'
    /// corrections differ from the arcs at a coarse vertex by far more than a thin cell's
    /// height (an extruded O-grid's three-layer wall went back to the chords). Directions of
    /// the sample along which the sources do not change (across the layers) are dropped
    /// first; `None` when the rest is not a boundary edge or face.
    fn inherited_arc(
        &self,
        topo: &Topology,
        mesh: &LinearMesh,
        ks: &[usize],
        cs: &[usize],
        l: [usize; 3],
    ) -> Option<DVec3> {
        let src: Vec<u32> = ks
            .iter()
            .map(|&k| self.sources.get(k).copied().filter(|&s| s != NONE))
            .collect::<Option<_>>()?;
        let gamma = ks
            .iter()
            .map(|&k| self.models[k].map_or(0.0, |m| m.weight))
            .sum::<f64>()
            / ks.len() as f64;
        // Corner i's parameters; the corner across free direction d from corner i.
        let par = |i: usize| HEX_VERTEX_PARAMS[cs[i]];
        let across = |i: usize, d: usize| {
            (0..cs.len()).find(|&j| (0..3).all(|k| (par(j)[k] == par(i)[k]) != (k == d)))
        };
        let mut free: Vec<usize> = (0..3).filter(|&k| l[k] == 1).collect();
        let mut keep: Vec<usize> = (0..cs.len()).collect();
        while let Some(pos) = free.iter().position(|&d| {
            keep.iter()
                .all(|&i| across(i, d).is_some_and(|j| src[j] == src[i]))
        }) {
            let d = free.remove(pos);
            keep.retain(|&i| par(i)[d] == 0);
        }
        let corners: Vec<u32> = keep.iter().map(|&i| src[i]).collect();
        let edge = |a: u32, b: u32| {
            topo.edges
                .binary_search(&[a.min(b), a.max(b)])
                .is_ok_and(|id| topo.edge_on_boundary[id])
        };
        let normals: Vec<ArcVertex> = corners
            .iter()
            .map(|&v| self.arc_normals[v as usize])
            .collect::<Option<_>>()?;
        if !normals.iter().any(|a| a.coarse) {
            return None;
        }
        let x = |i: usize| DVec3::from(mesh.coords[corners[i] as usize]);
        let n = |i: usize| DVec3::from(normals[i].normal);
        let target =
            |i: usize, j: usize| ArcVertex::edge_target([&normals[i], &normals[j]], [x(i), x(j)]);
        let arc = match free.len() {
            1 if corners[0] != corners[1] && edge(corners[0], corners[1]) => target(0, 1)?,
            2 => {
                // Corners in the face's lattice order along the two remaining directions.
                let (mut xf, mut nf, mut vf) = ([DVec3::ZERO; 4], [DVec3::ZERO; 4], [NONE; 4]);
                let mut at = [0; 4];
                for (i, &c) in keep.iter().enumerate() {
                    let p = par(c);
                    let j = p[free[0]] as usize + 2 * p[free[1]] as usize;
                    (xf[j], nf[j], vf[j], at[j]) = (x(i), n(i), corners[i], i);
                }
                let [a, b, c, d] = vf;
                if a == NONE || !(edge(a, b) && edge(a, c) && edge(b, d) && edge(c, d)) {
                    return None;
                }
                arcs::face_arc(&xf, &nf, |i, j| target(at[i], at[j]))?
            }
            _ => return None,
        };
        Some(gamma * arc)
    }

    /// The boundary facet or 3D boundary edge of element `e` at lattice point `l` (an edge
    /// with one lattice coordinate 1, a 3D face with two), if it is on the boundary.
    fn boundary_entity(&self, topo: &Topology, e: usize, l: [usize; 3]) -> Option<BoundaryEntity> {
        let dim = self.dim;
        let ones = (0..dim).filter(|&k| l[k] == 1).count();
        if dim == 2 || ones == 2 {
            let k = (0..dim).find(|&k| l[k] != 1).unwrap();
            let f = topo.element_facet(e, 2 * k + l[k] / 2);
            return (topo.facet_elements[f as usize][1] == NONE)
                .then_some(BoundaryEntity::Facet(f));
        }
        let k = (0..3).find(|&k| l[k] == 1).unwrap();
        let others = [(k + 1) % 3, (k + 2) % 3];
        let others = [others[0].min(others[1]), others[0].max(others[1])];
        let i = l[others[0]] / 2 + 2 * (l[others[1]] / 2);
        debug_assert_eq!(
            HEX_EDGES[4 * k + i].map(|c| HEX_VERTEX_PARAMS[c][others[0]] as usize * 2),
            [l[others[0]]; 2]
        );
        let ed = topo.element_edges[e * 12 + 4 * k + i];
        topo.edge_on_boundary[ed as usize].then_some(BoundaryEntity::Edge(ed))
    }
}

/// First pass: the one-ring model of each smooth boundary vertex (2D parabola, 3D quadric over
/// its fan `fan`) and its length scale ℓ; `None` at feature, non-manifold or degenerate
/// vertices and in the interior.
fn one_ring_models(
    mesh: &LinearMesh,
    topo: &Topology,
    params: &SmoothParams,
    features: Option<&Features>,
    fan: &[Vec<u32>],
    seam: &Seam,
) -> (Vec<Option<VertexModel>>, Vec<f64>) {
    let nv = mesh.n_vertices();
    let cos_max = params.feature_angle_deg.to_radians().cos();
    // Made by the workers, not written out on the calling thread (`ell` is calloc's zeros).
    let mut models: Vec<Option<VertexModel>> = (0..nv).into_par_iter().map(|_| None).collect();
    let mut ell = vec![0.0; nv];
    let mut non_manifold = vec![false; nv];
    for &v in &topo.non_manifold.vertices {
        non_manifold[v as usize] = true;
    }
    let x = |v: u32| mesh.coords[v as usize];
    // Each boundary vertex's model depends only on its fan: in parallel.
    models
        .par_iter_mut()
        .zip(ell.par_iter_mut())
        .enumerate()
        .with_min_len(1024)
        .for_each(|(v, (model, ell))| {
            if !topo.vertex_on_boundary[v]
                || non_manifold[v]
                || features.is_some_and(|f| f.vertex_mask[v])
            {
                return;
            }
            let xv = mesh.coords[v];
            if mesh.dim == 2 {
                let other = |f: u32| {
                    let e = topo.edges[f as usize];
                    if e[0] as usize == v { e[1] } else { e[0] }
                };
                // A wall ending on a seam goes on through its partner across.
                let (a, b) = match (fan[v].len(), seam.across(v)) {
                    (2, _) => (x(other(fan[v][0])), x(other(fan[v][1]))),
                    (1, Some((w, t))) => match seam.next(topo, w, None) {
                        Some(b) => (x(other(fan[v][0])), t.apply(x(b))),
                        None => return,
                    },
                    _ => return,
                };
                let xd = DVec3::from(xv);
                let (ua, ub) = (DVec3::from(a) - xd, DVec3::from(b) - xd);
                let (la, lb) = (ua.length(), ub.length());
                if la == 0.0 || lb == 0.0 {
                    return;
                }
                *ell = 0.5 * (la + lb);
                // Turning angle between the edges ≤ 2 × the feature angle.
                let cos_turn = -ua.dot(ub) / (la * lb);
                if cos_turn < (2.0 * params.feature_angle_deg.to_radians()).cos() {
                    return;
                }
                *model = fit_parabola(xv, a, b).map(|(normal, h)| VertexModel {
                    normal,
                    h,
                    weight: 1.0,
                });
            } else {
                // A wall's fan cut by a seam is completed by the other side's.
                let fitted = match seam.fan_across(mesh, topo, v as u32) {
                    Some((quads, nb)) if quads.len() >= 3 => {
                        quad_fan_model(DVec3::from(xv), &quads, &nb, cos_max)
                    }
                    Some(_) => return,
                    None if fan[v].len() < 3 => return,
                    None => fan_model(mesh, topo, v as u32, &fan[v], cos_max),
                };
                if let Some((m, l, _)) = fitted {
                    *ell = l;
                    *model = m;
                }
            }
        });
    (models, ell)
}

/// Second pass: height functions of degree up to four over two rings of boundary vertices,
/// reached through smooth vertices only (so never across a feature). Replaces the refined
/// vertices' `models` and returns their [`HigherModel`]s.
fn two_ring_models(
    mesh: &LinearMesh,
    topo: &Topology,
    fan: &[Vec<u32>],
    models: &mut [Option<VertexModel>],
    ell: &[f64],
    cos_max: f64,
    seam: &Seam,
) -> Vec<Option<HigherModel>> {
    let nv = mesh.n_vertices();
    let models_ref = &*models;
    let refined: Vec<Option<(VertexModel, HigherModel)>> = (0..nv)
        .into_par_iter()
        .with_min_len(1024)
        .map_init(
            || (RingScratch::default(), RingScratch::default()),
            |(scratch, across), v| {
                let m = models_ref[v]?;
                let mut ring = two_ring(mesh, topo, fan, models_ref, v as u32, cos_max, scratch);
                let mut one_sided = scratch.one_sided(models_ref);
                if mesh.dim == 2 {
                    seam.extend_ring(mesh, topo, models_ref, v as u32, &scratch.first, &mut ring);
                } else {
                    let ends_one_sided = seam.extend_ring_3d(
                        mesh,
                        topo,
                        models_ref,
                        (v as u32, cos_max),
                        (&scratch.first, across),
                        &mut ring,
                    );
                    one_sided |= ends_one_sided;
                }
                // Next to a feature the ring is one-sided (see `two_ring`).
                let how = if one_sided {
                    Height::ONE_SIDED
                } else {
                    Height::CENTRED
                };
                refine_model(mesh.dim, mesh.coords[v], &m, &ring, ell[v], how)
            },
        )
        .collect();
    // The refined models replace the first pass's and the height functions are kept, by the
    // workers.
    models
        .par_iter_mut()
        .zip(refined)
        .with_min_len(1024)
        .map(|(model, r)| {
            let (m, h) = r?;
            *model = Some(m);
            Some(h)
        })
        .collect()
}

/// A vertex as seen from another vertex's side of the periodic seams: where the rigid map
/// `map` carries it (`None`: where it is).
#[derive(Clone, Copy, Debug)]
struct Seen {
    v: u32,
    map: Option<Rigid>,
}

/// The walls' continuations across periodic seams ([`SmoothTargets::build_shared`]).
struct Seam<'a> {
    /// The mesh's dimension.
    dim: usize,
    /// Boundary facets at each vertex.
    fan: &'a [Vec<u32>],
    /// Per vertex (empty: none), the partner across the seam and the map from its side.
    partners: &'a [Option<(u32, Rigid)>],
    /// The seams' vertex pairs, sorted (empty: none).
    links: &'a [SeamLink],
}

impl Seam<'_> {
    /// The partner of 2D wall end `v` and the map carrying its side onto v's.
    fn across(&self, v: usize) -> Option<(u32, &Rigid)> {
        let (w, t) = self.partners.get(v)?.as_ref()?;
        (self.dim == 2 && self.fan[v].len() == 1 && self.fan[*w as usize].len() == 1)
            .then_some((*w, t))
    }

    /// The wall vertices glued to 3D wall vertex `v` on a seam, each with the map carrying
    /// its side onto v's: every image across the seams ([`Seam::images`]; a corner where two
    /// seams meet has three), else the partner alone; empty away from seams.
    fn across_3d(&self, v: usize) -> Vec<(u32, Rigid)> {
        let Some(Some((w, t))) = self.partners.get(v) else {
            return Vec::new();
        };
        if self.dim != 3 || self.fan[v].is_empty() {
            return Vec::new();
        }
        let images: Vec<(u32, Rigid)> = if self.links.is_empty() {
            vec![(*w, *t)]
        } else {
            self.images(Seen {
                v: v as u32,
                map: None,
            })
            .into_iter()
            .filter_map(|s| Some((s.v, s.map?)))
            .collect()
        };
        images
            .into_iter()
            .filter(|&(u, _)| !self.fan[u as usize].is_empty())
            .collect()
    }

    /// The fan of 3D wall vertex `v` on a seam completed by those of the vertices glued to it
    /// ([`fan_across`]); `None` away from seams.
    fn fan_across(
        &self,
        mesh: &LinearMesh,
        topo: &Topology,
        v: u32,
    ) -> Option<(Vec<[DVec3; 4]>, Vec<DVec3>)> {
        let across = self.across_3d(v as usize);
        if across.is_empty() {
            return None;
        }
        let (mut quads, mut nb) = (Vec::new(), Vec::new());
        for (w, t) in across {
            let (q, n) = fan_across(
                mesh,
                topo,
                (v, &self.fan[v as usize]),
                (w, &self.fan[w as usize]),
                &t,
            );
            quads.extend(if quads.is_empty() {
                q
            } else {
                q[self.fan[v as usize].len()..].to_vec()
            });
            nb.extend(n);
        }
        dedup_points(DVec3::from(mesh.coords[v as usize]), &mut nb);
        Some((quads, nb))
    }

    /// Adds to the two-ring `ring` of 3D wall vertex `v` (first ring `first`) the wall points
    /// across the seams it reaches, carried onto v's side, so that the ring is the one of the
    /// glued wall: at a vertex on a seam the two-rings of the vertices glued to it (found with
    /// `scratch`), from a smooth vertex on a seam in the first ring the first rings of those
    /// glued to it. Points met on both sides (the seam's own) are kept once. Returns whether
    /// a first ring across reached a vertex without a smooth model (the ring is then
    /// one-sided, as on v's side).
    fn extend_ring_3d(
        &self,
        mesh: &LinearMesh,
        topo: &Topology,
        models: &[Option<VertexModel>],
        (v, cos_max): (u32, f64),
        (first, scratch): (&[u32], &mut RingScratch),
        ring: &mut Vec<[f64; 3]>,
    ) -> bool {
        if self.partners.is_empty() {
            return false;
        }
        let len = ring.len();
        let mut one_sided = false;
        for (w, t) in self.across_3d(v as usize) {
            let across = two_ring(mesh, topo, self.fan, models, w, cos_max, scratch);
            ring.extend(across.iter().map(|&p| t.apply(p)));
            one_sided |= scratch.one_sided(models);
        }
        for &u in first {
            if models[u as usize].is_none() {
                continue;
            }
            for (w, t) in self.across_3d(u as usize) {
                for &f in &self.fan[w as usize] {
                    ring.extend(
                        topo.facet_vertices(f as usize)
                            .iter()
                            .filter(|&&y| y != w)
                            .map(|&y| t.apply(mesh.coords[y as usize])),
                    );
                }
            }
        }
        if ring.len() > len {
            let mut pts: Vec<DVec3> = ring.iter().map(|&p| DVec3::from(p)).collect();
            dedup_points(DVec3::from(mesh.coords[v as usize]), &mut pts);
            *ring = pts.into_iter().map(Into::into).collect();
        }
        one_sided
    }

    /// Where `s` lies on the side of the vertex it is seen from.
    fn at(&self, mesh: &LinearMesh, s: Seen) -> DVec3 {
        let x = mesh.coords[s.v as usize];
        DVec3::from(s.map.map_or(x, |t| t.apply(x)))
    }

    /// The boundary quads around `s`, each as its corners in the facet's order starting from
    /// the centre: its own fan and, at a wall vertex on seams, the fans of the vertices glued
    /// to it carried across ([`Seam::images`]), all seen from the side `s` is seen from.
    fn star(&self, topo: &Topology, s: Seen) -> Vec<[Seen; 4]> {
        let quads = |v: u32, map: Option<Rigid>| {
            self.fan[v as usize].iter().filter_map(move |&f| {
                let q = topo.facet_vertices(f as usize);
                let i = q.iter().position(|&u| u == v)?;
                (q.len() == 4).then(|| {
                    std::array::from_fn(|k| Seen {
                        v: q[(i + k) % 4],
                        map,
                    })
                })
            })
        };
        self.images(s)
            .into_iter()
            .flat_map(|u| quads(u.v, u.map))
            .collect()
    }

    /// `s` and the vertices glued to it across the seams (through `links`, transitively: a
    /// corner where two seams meet has three), each seen from the side `s` is seen from.
    fn images(&self, s: Seen) -> Vec<Seen> {
        let mut out = vec![s];
        let mut k = 0;
        while let Some(&u) = out.get(k) {
            let first = self.links.partition_point(|l| l.0 < u.v);
            for &(_, w, t) in self.links[first..].iter().take_while(|l| l.0 == u.v) {
                if out.iter().all(|o| o.v != w) {
                    let map = Some(u.map.map_or(t, |m| m.after(&t)));
                    out.push(Seen { v: w, map });
                }
            }
            k += 1;
        }
        out
    }

    /// [`grid_pairs`] of `s` over its [`Seam::star`]: the two opposite pairs of its edge
    /// neighbours when the star is four quads, a wall's grid lines going on across a seam.
    fn grid_pairs(&self, mesh: &LinearMesh, topo: &Topology, s: Seen) -> Option<[(Seen, Seen); 2]> {
        let star = self.star(topo, s);
        if star.len() != 4 {
            return None;
        }
        let sides: Vec<[Seen; 2]> = star.iter().map(|q| [q[1], q[3]]).collect();
        let centre = self.at(mesh, s);
        let spread = sides
            .iter()
            .flatten()
            .map(|&u| (self.at(mesh, u) - centre).length())
            .fold(0.0, f64::max);
        let same =
            |a: Seen, b: Seen| (self.at(mesh, a) - self.at(mesh, b)).length() <= 1e-6 * spread;
        let mut nbs: Vec<Seen> = Vec::with_capacity(4);
        for &u in sides.iter().flatten() {
            if !nbs.iter().any(|&n| same(n, u)) {
                nbs.push(u);
            }
        }
        if nbs.len() != 4 {
            return None;
        }
        let holds = |side: &[Seen; 2], u: Seen| side.iter().any(|&y| same(y, u));
        let opposite = |w: Seen| {
            nbs.iter().copied().find(|&u| {
                !same(u, w) && !sides.iter().any(|side| holds(side, u) && holds(side, w))
            })
        };
        let a = nbs[0];
        let b = opposite(a)?;
        let c = nbs.iter().copied().find(|&u| !same(u, a) && !same(u, b))?;
        let d = opposite(c)?;
        Some([(a, b), (c, d)])
    }

    /// The vertex next to `a` along the grid line coming from the point `from` (a neighbour
    /// of `a`), across a seam where the line crosses one.
    fn beyond(&self, mesh: &LinearMesh, topo: &Topology, a: Seen, from: DVec3) -> Option<Seen> {
        let pairs = self.grid_pairs(mesh, topo, a)?;
        let tol = 1e-6 * (self.at(mesh, a) - from).length();
        let is_from = |u: Seen| (self.at(mesh, u) - from).length() <= tol;
        pairs.into_iter().find_map(|(p, q)| {
            if is_from(p) {
                Some(q)
            } else {
                is_from(q).then_some(p)
            }
        })
    }

    /// Whether 3D wall vertex `v` lies on a seam or has an edge neighbour on one.
    fn near(&self, topo: &Topology, v: u32) -> bool {
        let on = |u: u32| {
            let first = self.links.partition_point(|l| l.0 < u);
            self.links.get(first).is_some_and(|l| l.0 == u)
        };
        on(v)
            || self
                .star(topo, Seen { v, map: None })
                .iter()
                .any(|q| on(q[1].v) || on(q[3].v))
    }

    /// The wall vertex next to `u` along the boundary chain, away from `from`.
    fn next(&self, topo: &Topology, u: u32, from: Option<u32>) -> Option<u32> {
        self.fan[u as usize]
            .iter()
            .map(|&f| {
                let e = topo.edges[f as usize];
                if e[0] == u { e[1] } else { e[0] }
            })
            .find(|&n| Some(n) != from)
    }

    /// Adds to the two-ring `ring` of `v` (first ring `first`) the wall points across a seam
    /// the chain reaches within two steps, carried onto v's side: from a seam end v its
    /// partner's two next vertices (the second through a smooth vertex only, as
    /// [`two_ring`]), from a smooth seam end in the first ring its partner's next.
    fn extend_ring(
        &self,
        mesh: &LinearMesh,
        topo: &Topology,
        models: &[Option<VertexModel>],
        v: u32,
        first: &[u32],
        ring: &mut Vec<[f64; 3]>,
    ) {
        if self.partners.is_empty() {
            return;
        }
        let x = |u: u32| mesh.coords[u as usize];
        if let Some((w, t)) = self.across(v as usize)
            && let Some(b) = self.next(topo, w, None)
        {
            ring.push(t.apply(x(b)));
            if models[b as usize].is_some()
                && let Some(c) = self.next(topo, b, Some(w))
            {
                ring.push(t.apply(x(c)));
            }
        }
        for &u in first {
            if models[u as usize].is_none() {
                continue;
            }
            if let Some((w, t)) = self.across(u as usize)
                && let Some(b) = self.next(topo, w, None)
            {
                ring.push(t.apply(x(b)));
            }
        }
    }
}

/// A smooth boundary vertex of a 3D mesh with a coarse vertex ([`coarse_normals`]).
#[derive(Clone, Copy, Debug, PartialEq)]
struct ArcVertex {
    normal: [f64; 3],
    /// Whether a vertex sharing a boundary facet turns its normal by more than
    /// [`arcs::COARSE_TURN_DEG`].
    coarse: bool,
    /// At a coarse regular vertex, the conics of its two grid lines where they are fixed and
    /// their planes hold the normal ([`arcs::LineConic::is_normal_section`]).
    lines: [Option<arcs::LineConic>; 2],
}

impl ArcVertex {
    /// Values per vertex in a record of [`shared_coarse_normals`].
    const LEN: usize = 5 + 2 * arcs::LineConic::LEN;

    fn write(&self, r: &mut [f64]) {
        r[0] = 1.0;
        r[1..4].copy_from_slice(&self.normal);
        r[4] = f64::from(u8::from(self.coarse));
        for (k, line) in self.lines.iter().enumerate() {
            if let Some(c) = line {
                c.write(&mut r[5 + k * arcs::LineConic::LEN..]);
            }
        }
    }

    fn read(r: &[f64]) -> Option<ArcVertex> {
        let l = arcs::LineConic::LEN;
        (r[0] > 0.0).then(|| ArcVertex {
            normal: [r[1], r[2], r[3]],
            coarse: r[4] > 0.0,
            lines: [0, 1].map(|k| arcs::LineConic::read(&r[5 + k * l..5 + (k + 1) * l])),
        })
    }

    /// Displacement of the midpoint of the boundary edge between `v[0]` and `v[1]` (at `x`):
    /// the mean of the points of the grid-line conics of its ends that hold it, else the
    /// circular arc on their normals ([`arcs::edge_arc`]).
    fn edge_target(v: [&ArcVertex; 2], x: [DVec3; 2]) -> Option<DVec3> {
        let (mut sum, mut k) = (DVec3::ZERO, 0.0);
        for (i, j) in [(0, 1), (1, 0)] {
            if let Some(d) = v[i]
                .lines
                .iter()
                .flatten()
                .find_map(|c| c.edge_midpoint(x[i], x[j]))
            {
                sum += d;
                k += 1.0;
            }
        }
        if k > 0.0 {
            return Some(sum / k);
        }
        arcs::edge_arc(x[0], x[1], v[0].normal.into(), v[1].normal.into())
    }
}

/// The quads of the boundary facets `own` at `v` and of the partner `w`'s facets `theirs`
/// carried over by the periodic map `t` (corners in the facets' order), and their distinct
/// corners other than v: a wall's fan cut by a periodic seam, completed by the other side's.
pub(super) fn fan_across(
    mesh: &LinearMesh,
    topo: &Topology,
    (v, own): (u32, &[u32]),
    (w, theirs): (u32, &[u32]),
    t: &Rigid,
) -> (Vec<[DVec3; 4]>, Vec<DVec3>) {
    let x = |u: u32| DVec3::from(mesh.coords[u as usize]);
    let there = |u: u32| DVec3::from(t.apply(mesh.coords[u as usize]));
    let mut quads = Vec::with_capacity(own.len() + theirs.len());
    let mut nb = Vec::new();
    for &f in own {
        let q = topo.faces[f as usize];
        quads.push(q.map(x));
        nb.extend(q.iter().filter(|&&u| u != v).map(|&u| x(u)));
    }
    for &f in theirs {
        let q = topo.faces[f as usize];
        quads.push(q.map(there));
        nb.extend(q.iter().filter(|&&u| u != w).map(|&u| there(u)));
    }
    dedup_points(x(v), &mut nb);
    (quads, nb)
}

/// Removes from `pts` the points within 10⁻⁶ of their spread around `x` of `x` or of an
/// earlier point: the seam's points reached on both sides of a periodic seam, once directly
/// and once carried over by the transform (which matches them to the pair's tolerance only).
pub(super) fn dedup_points(x: DVec3, pts: &mut Vec<DVec3>) {
    let spread = pts.iter().map(|&p| (p - x).length()).fold(0.0, f64::max);
    let tol = 1e-6 * spread;
    let mut kept: Vec<DVec3> = Vec::with_capacity(pts.len());
    for &p in pts.iter() {
        if (p - x).length() > tol && kept.iter().all(|&q| (p - q).length() > tol) {
            kept.push(p);
        }
    }
    *pts = kept;
}

/// The normals of the smooth boundary vertices of a 3D mesh, whether each is coarse and the
/// coarse regular vertices' grid-line conics ([`ArcVertex`]), or nothing when no vertex is
/// coarse (the targets then come from the models alone).
fn coarse_normals(
    mesh: &LinearMesh,
    topo: &Topology,
    fan: &[Vec<u32>],
    models: &[Option<VertexModel>],
    seam: &Seam,
) -> Vec<Option<ArcVertex>> {
    if mesh.dim != 3 {
        return Vec::new();
    }
    let cos_turn = arcs::COARSE_TURN_DEG.to_radians().cos();
    let x = |w: u32| DVec3::from(mesh.coords[w as usize]);
    // Whether a vertex of the facets `fan` turns its normal (carried by `turn`) from `n`.
    let turns = |fan: &[u32], n: DVec3, turn: &dyn Fn([f64; 3]) -> [f64; 3]| {
        fan.iter().any(|&f| {
            topo.facet_vertices(f as usize).iter().any(|&w| {
                models[w as usize]
                    .is_some_and(|m| DVec3::from(turn(m.normal)).dot(n).abs() < cos_turn)
            })
        })
    };
    // The two grid lines at `v` (opposite pairs of edge neighbours) and the next points beyond
    // them that have a model.
    type Lines = ([(DVec3, DVec3); 2], [Option<[DVec3; 2]>; 2]);
    let grid_lines = |v: u32| -> Option<Lines> {
        let own = grid_pairs(topo, &fan[v as usize], v).map(|pairs| {
            // The next vertex along the grid line from v through its neighbour a.
            let beyond = |a: u32| {
                grid_pairs(topo, &fan[a as usize], a)?
                    .into_iter()
                    .find_map(|(p, q)| (p == v).then_some(q).or((q == v).then_some(p)))
                    .filter(|&w| models[w as usize].is_some())
            };
            let outer = pairs.map(|(a, b)| Some([x(beyond(a)?), x(beyond(b)?)]));
            (pairs.map(|(a, b)| (x(a), x(b))), outer)
        });
        if own.is_some_and(|(_, outer)| outer.iter().all(Option::is_some))
            || seam.links.is_empty()
            || !seam.near(topo, v)
        {
            return own;
        }
        // A grid line cut by a periodic seam goes on over the other side, carried across.
        let me = Seen { v, map: None };
        let pairs = seam.grid_pairs(mesh, topo, me)?;
        let xv = x(v);
        let beyond = |a: Seen| {
            seam.beyond(mesh, topo, a, xv)
                .filter(|w| models[w.v as usize].is_some())
                .map(|w| seam.at(mesh, w))
        };
        let outer = pairs.map(|(a, b)| Some([beyond(a)?, beyond(b)?]));
        Some((
            pairs.map(|(a, b)| (seam.at(mesh, a), seam.at(mesh, b))),
            outer,
        ))
    };
    let out: Vec<Option<ArcVertex>> = (0..mesh.n_vertices())
        .into_par_iter()
        .with_min_len(1024)
        .map(|v| {
            let n = models[v]?.normal;
            // At a wall vertex on seams the fan goes on over those glued to it, carried across.
            let coarse = turns(&fan[v], n.into(), &|m| m)
                || seam
                    .images(Seen {
                        v: v as u32,
                        map: None,
                    })
                    .iter()
                    .skip(1)
                    .any(|u| {
                        let t = u.map.expect("an image across a seam has a map");
                        turns(&fan[u.v as usize], n.into(), &|m| t.rotate(m))
                    });
            // At a coarse regular vertex the grid lines' circles give the normal far more
            // accurately than the fan (the arcs need it to a fraction of a degree).
            let mut lines = [None; 2];
            let n = coarse
                .then(|| grid_lines(v as u32))
                .flatten()
                .and_then(|(pairs, outer)| {
                    let xv = x(v as u32);
                    for k in 0..2 {
                        lines[k] = outer[k]
                            .and_then(|o| arcs::LineConic::fit(pairs[k].0, xv, pairs[k].1, o));
                    }
                    arcs::grid_normal(xv, pairs, outer, n.into())
                })
                .map_or(n, Into::into);
            let lines = lines.map(|c| c.filter(|c| c.is_normal_section(n.into())));
            Some(ArcVertex {
                normal: n,
                coarse,
                lines,
            })
        })
        .collect();
    let any = out.par_iter().any(|a| a.is_some_and(|a| a.coarse));
    if any { out } else { Vec::new() }
}

/// [`coarse_normals`] on a rank's part of a distributed mesh: the whole mesh's for every
/// vertex the rank holds. A computed vertex's flag reads the two-ring models of its fan's
/// vertices and its grid normal whether the vertices two steps along its grid lines have a
/// model: vertices up to two rings out, whose own fans and two rings reach past the ghost
/// rings. So the models' normals (and whether there is one) of the vertices the rank does
/// not compute are first taken from ranks that compute them, and the arc normals found from
/// them on the computed vertices are then handed to the ranks holding those as ghosts (the
/// interior samples read their sources' arc normals, [`SmoothTargets::inherited_arc`]).
/// Collective; empty where no rank has a coarse vertex (fringes of ghost rings included).
fn shared_coarse_normals(
    mesh: &LinearMesh,
    topo: &Topology,
    fan: &[Vec<u32>],
    models: &[Option<VertexModel>],
    seam: &Seam,
    share: &dyn InheritShare,
) -> Vec<Option<ArcVertex>> {
    if !share.any(!coarse_normals(mesh, topo, fan, models, seam).is_empty()) {
        return Vec::new();
    }
    let (nv, n) = (mesh.n_vertices(), RECORD_LEN);
    let mut records = vec![0.0; nv * n];
    for (r, m) in records.chunks_exact_mut(n).zip(models) {
        if let Some(m) = m {
            r[0] = 1.0;
            r[1..4].copy_from_slice(&m.normal);
        }
    }
    share.exchange_all(&mut records);
    let a3 = |r: &[f64]| [r[1], r[2], r[3]];
    let seen: Vec<Option<VertexModel>> = (0..nv)
        .map(|v| {
            let r = &records[v * n..(v + 1) * n];
            match share.computes(v) {
                true => models[v],
                false => (r[0] > 0.0).then(|| VertexModel {
                    normal: a3(r),
                    h: [[0.0; 3]; 3],
                    weight: 1.0,
                }),
            }
        })
        .collect();
    let mut arcs = coarse_normals(mesh, topo, fan, &seen, seam);
    arcs.resize(nv, None);
    records.fill(0.0);
    const { assert!(ArcVertex::LEN <= RECORD_LEN) };
    for (r, a) in records.chunks_exact_mut(n).zip(&arcs) {
        if let Some(a) = a {
            a.write(r);
        }
    }
    share.exchange_all(&mut records);
    for (v, a) in arcs.iter_mut().enumerate() {
        if !share.computes(v) {
            *a = ArcVertex::read(&records[v * n..(v + 1) * n]);
        }
    }
    arcs
}

/// The two opposite pairs of edge neighbours of `v` (its grid lines) when its boundary fan
/// `fan` is four quads around it, each neighbour in two of them.
fn grid_pairs(topo: &Topology, fan: &[u32], v: u32) -> Option<[(u32, u32); 2]> {
    if fan.len() != 4 {
        return None;
    }
    // Per quad, the two edge neighbours of v.
    let mut sides = [[0u32; 2]; 4];
    for (s, &f) in sides.iter_mut().zip(fan) {
        let q = topo.facet_vertices(f as usize);
        let i = q.iter().position(|&w| w == v)?;
        if q.len() != 4 {
            return None;
        }
        *s = [q[(i + 1) % 4], q[(i + 3) % 4]];
    }
    let mut nbs: Vec<u32> = sides.iter().flatten().copied().collect();
    nbs.sort_unstable();
    nbs.dedup();
    if nbs.len() != 4 {
        return None;
    }
    // The opposite of a neighbour shares no quad with it.
    let opposite = |w: u32| {
        nbs.iter()
            .copied()
            .find(|&u| u != w && !sides.iter().any(|s| s.contains(&u) && s.contains(&w)))
    };
    let a = nbs[0];
    let b = opposite(a)?;
    let c = nbs.iter().copied().find(|&u| u != a && u != b)?;
    let d = opposite(c)?;
    Some([(a, b), (c, d)])
}

/// A rank's part of a mesh distributed over ranks, as the interior inheritance
/// ([`SmoothTargets::build_shared`]) needs it: which vertices the rank computes, their place
/// in the whole mesh's vertex order, and the exchange of per-vertex records with the ranks
/// around it.
///
/// A rank computes the vertices of its own elements: their edge neighbours, their boundary
/// status and their boundary models are the whole mesh's (its ghost rings hold every element
/// around them and the facets their models read), while the fringe of its ghost rings is cut
/// out of the mesh and looks like boundary. Only computed vertices are sources and only they
/// are relaxed; every other vertex around them takes the record of a rank that computes it,
/// and the ranks repeat until no record changes, since a boundary layer's decay distance
/// reaches across many element rings.
pub trait InheritShare {
    /// Whether this rank computes local vertex `v` (a vertex of one of its own elements).
    fn computes(&self, v: usize) -> bool;
    /// Local vertex `v`'s place in the whole mesh's vertex order (the order of the serial
    /// run's vertex indices), below 2⁵³.
    fn order(&self, v: usize) -> u64;
    /// Collective: `records` holds [`RECORD_LEN`] values per local vertex; the records of
    /// the vertices this rank does not compute but whose neighbours it does (along the mesh
    /// edges or across a periodic seam: the other side's vertex glued to a computed one) are
    /// replaced by those of a rank that computes them.
    fn exchange(&self, records: &mut [f64]);
    /// Collective: [`InheritShare::exchange`] for every vertex this rank holds but does not
    /// compute (its whole ghost rings).
    fn exchange_all(&self, records: &mut [f64]);
    /// Collective: whether `local` is true on any rank.
    fn any(&self, local: bool) -> bool;
}

/// Values per vertex in the records of [`InheritShare::exchange`]: the distance to the source
/// (∞: none), the predecessor's distance and order, the source's order and boundary edge
/// length ℓ, its model's normal and H, and its height function's cubic and quartic terms (a
/// flag, plus 2 for a source carried across a rotation seam, then the terms).
pub const RECORD_LEN: usize = 5 + 3 + 9 + 1 + HigherModel::LEN;

/// A vertex's place in the inheritance: the distance along mesh edges to its source, the
/// distance and order of the predecessor on that path, and the source's slot ([`NONE`]:
/// none; below the vertex count a local vertex, above it a source received from another rank).
#[derive(Clone, Copy, Debug, PartialEq)]
struct Reach {
    dist: f64,
    via: (f64, u64),
    src: u32,
}

impl Reach {
    const NONE: Reach = Reach {
        dist: f64::INFINITY,
        via: (f64::INFINITY, u64::MAX),
        src: NONE,
    };

    /// Whether `self` is nearer than `other`: by distance, then by the predecessor's distance
    /// and order. The serial Dijkstra settles the vertices in that order of (distance, order)
    /// and keeps a vertex's first path among equal distances, so this is its choice, and a
    /// choice that does not depend on the order the relaxations come in.
    fn before(&self, other: &Reach) -> bool {
        (self.dist, self.via.0, self.via.1) < (other.dist, other.via.0, other.via.1)
    }
}

/// The model a source hands on, its boundary edge length ℓ and its order, and whether it was
/// carried across a rotation seam.
#[derive(Clone, Copy, Debug)]
pub(super) struct Source {
    pub model: VertexModel,
    pub higher: Option<HigherModel>,
    pub ell: f64,
    pub order: u64,
    pub turned: bool,
}

impl Source {
    /// The source as the other side of a seam sees it: its models carried by `t`.
    fn carried(&self, t: &Rigid) -> Source {
        Source {
            model: self.model.carried(t),
            higher: self.higher.map(|h| h.carried(t)),
            turned: self.turned || !t.is_translation(),
            ..*self
        }
    }

    /// The bits of the source's part of its record: sources with the same key are the same.
    fn key(&self) -> Vec<u64> {
        let mut out = [0.0; RECORD_LEN];
        self.write(&Reach::NONE, &mut out);
        out[3..].iter().map(|x| x.to_bits()).collect()
    }

    /// Writes `reach` from this source into `out` ([`RECORD_LEN`] values).
    fn write(&self, reach: &Reach, out: &mut [f64]) {
        out[..5].copy_from_slice(&[
            reach.dist,
            reach.via.0,
            reach.via.1 as f64,
            self.order as f64,
            self.ell,
        ]);
        out[5..8].copy_from_slice(&self.model.normal);
        for (k, row) in self.model.h.iter().enumerate() {
            out[8 + 3 * k..11 + 3 * k].copy_from_slice(row);
        }
        out[17] = f64::from(u8::from(self.higher.is_some()) + 2 * u8::from(self.turned));
        if let Some(h) = &self.higher {
            h.write(&mut out[18..]);
        }
    }

    /// The reach (its source slot unset) and source of a record, when it has a source.
    fn read(r: &[f64]) -> Option<(Reach, Source)> {
        if !r[0].is_finite() {
            return None;
        }
        let a3 = |i: usize| [r[i], r[i + 1], r[i + 2]];
        let reach = Reach {
            dist: r[0],
            via: (r[1], r[2] as u64),
            src: NONE,
        };
        let source = Source {
            model: VertexModel {
                normal: a3(5),
                h: [a3(8), a3(11), a3(14)],
                weight: 1.0,
            },
            higher: (r[17] % 2.0 != 0.0).then(|| HigherModel::read(&r[18..])),
            ell: r[4],
            order: r[3] as u64,
            turned: r[17] >= 2.0,
        };
        Some((reach, source))
    }
}

/// What the interior inheritance gives: how many interior vertices took a model, and per
/// vertex its source's local index (itself for a source; [`NONE`] without one, or with a
/// source another rank holds) and the source's boundary edge length ℓ (NaN without one).
#[derive(Debug, Default)]
struct Inherited {
    vertices: usize,
    sources: Vec<u32>,
    scale: Vec<f64>,
}

/// Interior vertices inherit the nearest smooth boundary vertex's model (Dijkstra along mesh
/// edges from the smooth boundary vertices that are not `in_plane_3d`, cut off at decay · ℓ)
/// with weight γ = 1 − d / (decay · ℓ), and its [`HigherModel`]; on a rank's part of a
/// distributed mesh (`share`), the whole mesh's ([`nearest_shared`]). The paths run across
/// periodic seams along `links` ([`SmoothTargets::build_shared`]), a source reached across
/// handed on through the seam's map. A vertex whose source lies across a rotation seam has
/// no source vertex in [`Inherited::sources`] (its arcs would be the other side's); across
/// translations it keeps it, the arcs' displacements being the same on both sides.
#[allow(clippy::too_many_arguments)]
fn inherit_interior(
    mesh: &LinearMesh,
    topo: &Topology,
    decay: f64,
    ell: &[f64],
    in_plane_3d: &dyn Fn(usize) -> bool,
    models: &mut [Option<VertexModel>],
    higher: &mut [Option<HigherModel>],
    (share, links): (Option<&dyn InheritShare>, &[SeamLink]),
) -> Inherited {
    let nv = mesh.n_vertices();
    let nearest = {
        let (models, higher) = (&*models, &*higher);
        let order = |v: u32| share.map_or(u64::from(v), |s| s.order(v as usize));
        let source = |v: usize| {
            let model = models[v].filter(|_| !in_plane_3d(v))?;
            Some(Source {
                model,
                higher: higher[v],
                ell: ell[v],
                order: order(v as u32),
                turned: false,
            })
        };
        let adj = adjacency(nv, topo.edges.iter().copied());
        let relaxable = |w: usize| !topo.vertex_on_boundary[w];
        let paths = Paths {
            adj: &adj,
            seams: &seam_adjacency(nv, links),
            relaxable: &relaxable,
        };
        nearest_shared(mesh, &paths, &source, decay, share)
    };
    let mut out = Inherited {
        vertices: 0,
        sources: vec![NONE; nv],
        scale: vec![f64::NAN; nv],
    };
    // A source another rank computed or one carried across a seam, by its order: the local
    // vertex of that order, where this rank holds it (the arcs of the interior samples read
    // the sources' vertices).
    let of_order: HashMap<u64, u32> = if nearest.at.iter().flatten().any(|n| n.local == NONE) {
        let order = |v: usize| share.map_or(v as u64, |s| s.order(v));
        (0..nv).map(|v| (order(v), v as u32)).collect()
    } else {
        HashMap::new()
    };
    for (v, n) in nearest.at.iter().enumerate() {
        let Some(n) = n else {
            continue;
        };
        let s = nearest.source(n);
        out.sources[v] = match n.local {
            _ if s.turned => NONE,
            NONE => of_order.get(&s.order).copied().unwrap_or(NONE),
            local => local,
        };
        out.scale[v] = s.ell;
        if !n.is_source {
            let g = 1.0 - n.dist / (decay * s.ell);
            if g > 0.0 {
                models[v] = Some(VertexModel {
                    weight: g,
                    ..s.model
                });
                higher[v] = s.higher;
                out.vertices += 1;
            }
        }
    }
    out
}

/// A vertex's nearest source ([`nearest_shared`]).
#[derive(Clone, Copy, Debug)]
pub(super) struct Nearest {
    /// Distance along the edges.
    pub dist: f64,
    /// The source's local index ([`NONE`]: a source another rank holds).
    pub local: u32,
    /// Whether the vertex is its own source.
    pub is_source: bool,
    /// The source's entry in [`NearestSources::sources`].
    source: u32,
}

/// What [`nearest_shared`] finds: per vertex its nearest source, if any, and the sources'
/// models once each (a vertex refers to its source's entry rather than holding a copy of the
/// model: most vertices of a large mesh have none, and a model is a few hundred bytes).
#[derive(Debug)]
pub(super) struct NearestSources {
    pub at: Vec<Option<Nearest>>,
    sources: Vec<Source>,
}

impl NearestSources {
    /// What `n`'s source hands on.
    pub fn source(&self, n: &Nearest) -> &Source {
        &self.sources[n.source as usize]
    }
}

/// Where the inheritance's paths run ([`nearest_shared`]): the mesh edges (`adj`,
/// [`adjacency`]), the periodic seams (`seams`, [`seam_adjacency`]; zero-length steps to the
/// same glued vertex on the other side, the source carried by the seam's map), and the
/// vertices that take a path (`relaxable`).
pub(super) struct Paths<'a> {
    pub adj: &'a (Vec<u32>, Vec<u32>),
    pub seams: &'a (Vec<u32>, Vec<(u32, Rigid)>),
    pub relaxable: &'a dyn Fn(usize) -> bool,
}

/// The steps across periodic seams of the vertices of `links` ((v, w, t): x_v = t x_w,
/// [`crate::spline::seam::SeamView::seam_links`]): offsets (`nv` + 1) into the list of
/// (other side's vertex, map carrying this side onto it). Empty `links`: no steps.
pub(super) fn seam_adjacency(
    nv: usize,
    links: &[(u32, u32, Rigid)],
) -> (Vec<u32>, Vec<(u32, Rigid)>) {
    let mut offsets = vec![0u32; nv + 1];
    for &(_, w, _) in links {
        offsets[w as usize + 1] += 1;
    }
    for i in 0..nv {
        offsets[i + 1] += offsets[i];
    }
    let mut fill = offsets.clone();
    let mut steps = vec![(0, Rigid::translation([0.0; 3])); links.len()];
    // From w the step goes to v, the map carrying w's side onto v's.
    for &(v, w, t) in links {
        steps[fill[w as usize] as usize] = (v, t);
        fill[w as usize] += 1;
    }
    (offsets, steps)
}

/// The sources of [`nearest_shared`] by slot: below the vertex count the computed sources
/// (`entry` into `table` by vertex), above it those received from other ranks and those
/// carried across seams (`extra`), each once (`slot_of`, by [`Source::key`]).
struct Slots {
    nv: usize,
    table: Vec<Source>,
    entry: Vec<u32>,
    extra: Vec<Source>,
    slot_of: HashMap<Vec<u64>, u32>,
}

impl Slots {
    fn get(&self, src: u32) -> &Source {
        match (src as usize).checked_sub(self.nv) {
            None => &self.table[self.entry[src as usize] as usize],
            Some(i) => &self.extra[i],
        }
    }

    /// The slot of `s`, added when new.
    fn slot(&mut self, s: Source) -> u32 {
        let (nv, extra) = (self.nv, &mut self.extra);
        *self.slot_of.entry(s.key()).or_insert_with(|| {
            extra.push(s);
            (nv + extra.len() - 1) as u32
        })
    }

    /// The slot of source `src` carried by `t`.
    fn carried(&mut self, src: u32, t: &Rigid) -> u32 {
        let s = self.get(src).carried(t);
        self.slot(s)
    }
}

/// Multi-source Dijkstra along `paths` ([`Paths`]): the vertices `source` gives a model to
/// are the sources, and a relaxable vertex takes the nearest path a neighbour (or its
/// partner across a seam) hands on within decay · ℓ of its source ([`Reach::before`]). On a
/// rank's part of a distributed mesh (`share`) the sources are its computed vertices and
/// those of the other ranks, whose distances and models come in as records over the ranks'
/// borders; each round relaxes the computed vertices from scratch from the latest records,
/// until no record changes on any rank. Each vertex's nearest path is the unique fixed point
/// of "a vertex takes the nearest of its neighbours' paths within their sources' cut-off",
/// ties going as in the serial Dijkstra, so the computed vertices get the serial result.
pub(super) fn nearest_shared(
    mesh: &LinearMesh,
    paths: &Paths,
    source: &dyn Fn(usize) -> Option<Source>,
    decay: f64,
    share: Option<&dyn InheritShare>,
) -> NearestSources {
    let nv = mesh.n_vertices();
    let computes = |v: usize| share.is_none_or(|s| s.computes(v));
    let order = |v: u32| share.map_or(u64::from(v), |s| s.order(v as usize));
    // The computed sources' models in `table`, in vertex order, and each vertex's entry
    // there (`NONE`: not a source).
    let mut table: Vec<Source> = Vec::new();
    let entry: Vec<u32> = (0..nv)
        .map(|v| match source(v).filter(|_| computes(v)) {
            Some(s) => {
                table.push(s);
                (table.len() - 1) as u32
            }
            None => NONE,
        })
        .collect();
    let relaxable = |w: usize| computes(w) && (paths.relaxable)(w);
    // The local slot of a computed source, to find it again among the records.
    let slot_of = match share {
        Some(_) => (0..nv)
            .filter(|&v| entry[v] != NONE)
            .map(|v| (table[entry[v] as usize].key(), v as u32))
            .collect(),
        None => HashMap::new(),
    };
    let mut slots = Slots {
        nv,
        table,
        entry,
        extra: Vec::new(),
        slot_of,
    };
    // The latest records of the vertices other ranks compute (none without `share`).
    let mut seeds = vec![Reach::NONE; if share.is_some() { nv } else { 0 }];
    let reach = loop {
        let mut reach: Vec<Reach> = (0..nv)
            .map(|v| match (slots.entry[v] != NONE, computes(v)) {
                (true, _) => Reach {
                    dist: 0.0,
                    via: (0.0, order(v as u32)),
                    src: v as u32,
                },
                (false, true) => Reach::NONE,
                (false, false) => seeds[v],
            })
            .collect();
        let walk = Walk {
            paths,
            relaxable: &relaxable,
            decay,
            order: &order,
        };
        nearest_sources(mesh, &walk, &mut reach, &mut slots);
        let Some(share) = share else {
            break reach;
        };
        let mut records = vec![0.0; nv * RECORD_LEN];
        for (r, out) in reach.iter().zip(records.chunks_exact_mut(RECORD_LEN)) {
            if r.src == NONE {
                out[0] = f64::INFINITY;
            } else {
                slots.get(r.src).write(r, out);
            }
        }
        share.exchange(&mut records);
        let mut changed = false;
        for v in (0..nv).filter(|&v| !computes(v)) {
            let new = match Source::read(&records[v * RECORD_LEN..(v + 1) * RECORD_LEN]) {
                None => Reach::NONE,
                Some((r, s)) => Reach {
                    src: slots.slot(s),
                    ..r
                },
            };
            changed |= new != seeds[v];
            seeds[v] = new;
        }
        if !share.any(changed) {
            break reach;
        }
    };
    // The received and carried sources follow the computed ones in the table.
    let n_local = slots.table.len();
    let at = reach
        .iter()
        .enumerate()
        .map(|(v, r)| {
            let i = r.src as usize;
            (r.src != NONE).then(|| Nearest {
                dist: r.dist,
                local: if i < nv { r.src } else { NONE },
                // A source's path starts at itself; any other vertex's at a neighbour.
                is_source: r.via.1 == order(v as u32),
                source: match i.checked_sub(nv) {
                    None => slots.entry[i],
                    Some(k) => (n_local + k) as u32,
                },
            })
        })
        .collect();
    let mut sources = slots.table;
    sources.extend(slots.extra);
    NearestSources { at, sources }
}

/// The neighbours of every vertex along `edges`: offsets (`nv` + 1) into the list of
/// neighbours.
pub(super) fn adjacency(
    nv: usize,
    edges: impl Iterator<Item = [u32; 2]> + Clone,
) -> (Vec<u32>, Vec<u32>) {
    let mut offsets = vec![0u32; nv + 1];
    for e in edges.clone() {
        offsets[e[0] as usize + 1] += 1;
        offsets[e[1] as usize + 1] += 1;
    }
    for i in 0..nv {
        offsets[i + 1] += offsets[i];
    }
    let mut fill = offsets.clone();
    let mut adj = vec![0u32; offsets[nv] as usize];
    for e in edges {
        for (a, b) in [(e[0], e[1]), (e[1], e[0])] {
            adj[fill[a as usize] as usize] = b;
            fill[a as usize] += 1;
        }
    }
    (offsets, adj)
}

/// How one round of [`nearest_sources`] walks: along `paths`, into the vertices
/// `relaxable` allows, within decay · ℓ of the source, settling by (distance, `order`).
struct Walk<'a> {
    paths: &'a Paths<'a>,
    relaxable: &'a dyn Fn(usize) -> bool,
    decay: f64,
    order: &'a dyn Fn(u32) -> u64,
}

/// Dijkstra along the edges and seams ([`Walk`]) from the vertices whose `reach` is finite:
/// a relaxable vertex takes the nearest path ([`Reach::before`]) a neighbour hands on within
/// its source's cut-off, a step across a seam handing on the source carried by the seam's
/// map (a new slot in `slots`) at the same distance; vertices are settled in the order of
/// (distance, order).
fn nearest_sources(mesh: &LinearMesh, walk: &Walk, reach: &mut [Reach], slots: &mut Slots) {
    let x = |v: u32| DVec3::from(mesh.coords[v as usize]);
    let ((offsets, adj), (seam_offsets, seams)) = (walk.paths.adj, walk.paths.seams);
    let order = walk.order;
    let mut heap = BinaryHeap::new();
    for (v, r) in reach.iter().enumerate() {
        if r.dist.is_finite() {
            heap.push(Reverse((r.dist.to_bits(), order(v as u32), v as u32)));
        }
    }
    while let Some(Reverse((d_bits, ov, v))) = heap.pop() {
        let d = f64::from_bits(d_bits);
        let r = reach[v as usize];
        if d > r.dist {
            continue;
        }
        let cut = walk.decay * slots.get(r.src).ell;
        let (i, j) = (offsets[v as usize], offsets[v as usize + 1]);
        let across = seam_offsets
            .get(v as usize..v as usize + 2)
            .map_or(&[][..], |o| &seams[o[0] as usize..o[1] as usize]);
        let steps = adj[i as usize..j as usize]
            .iter()
            .map(|&w| (w, None))
            .chain(across.iter().map(|(w, t)| (*w, Some(t))));
        for (w, t) in steps {
            if !(walk.relaxable)(w as usize) {
                continue;
            }
            let nd = match t {
                None => d + (x(w) - x(v)).length(),
                Some(_) => d,
            };
            let next = Reach {
                dist: nd,
                via: (d, ov),
                src: r.src,
            };
            if nd < cut && next.before(&reach[w as usize]) {
                let src = t.map_or(r.src, |t| slots.carried(r.src, t));
                reach[w as usize] = Reach { src, ..next };
                heap.push(Reverse((nd.to_bits(), order(w), w)));
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::one_ring::fit_quadric;
    use super::*;

    /// On a circle sampled unevenly (neighbouring spacings in ratio 1 : 1.5), the corrected
    /// chord midpoint converges to the circle at third order or better; the chord at second.
    #[test]
    fn parabola_model_converges_on_circles() {
        let c = |t: f64| [t.cos(), t.sin(), 0.0];
        let mut errs = Vec::new();
        for h in [0.2, 0.1, 0.05] {
            let (t0, t1, t2) = (0.3 - h, 0.3, 0.3 + 1.5 * h);
            let (n, hm) = fit_parabola(c(t1), c(t0), c(t2)).unwrap();
            let m = VertexModel {
                normal: n,
                h: hm,
                weight: 1.0,
            };
            let (a, b) = (c(t1), c(t2));
            let p = [0.5 * (a[0] + b[0]), 0.5 * (a[1] + b[1]), 0.0];
            let q = DVec3::from(p) + DVec3::from(m.correction(p, &[a, b], 0.5));
            errs.push((
                (q.length() - 1.0).abs(),
                (DVec3::from(p).length() - 1.0).abs(),
            ));
        }
        for w in errs.windows(2) {
            assert!(w[0].0 / w[1].0 > 7.0, "{errs:?}");
            assert!(w[0].1 / w[1].1 < 4.5, "{errs:?}");
        }
        assert!(errs[2].0 < 0.01 * errs[2].1, "{errs:?}");
    }

    /// On a paraboloid the 3D quadric model is exact: face-centre targets lie on the surface.
    #[test]
    fn quadric_model_is_exact_on_quadrics() {
        let g = |u: f64, v: f64| [u, v, 0.3 * u * u - 0.4 * u * v + 0.9 * v * v + 0.2 * u];
        let x0 = g(0.0, 0.0);
        let mut pts = Vec::new();
        for (u, v) in [
            (-0.1, 0.0),
            (0.12, 0.01),
            (0.0, -0.1),
            (0.0, 0.11),
            (0.1, 0.1),
            (-0.1, -0.12),
        ] {
            pts.push((DVec3::from(g(u, v)) - DVec3::from(x0)).into());
        }
        let n0 = [0.0, 0.0, 1.0];
        let (n, h) = fit_quadric(n0, &pts, 0.1).unwrap();
        let m = VertexModel {
            normal: n,
            h,
            weight: 1.0,
        };
        let xs = [g(0.0, 0.0), g(0.1, 0.0), g(0.1, 0.1), g(0.0, 0.1)];
        let p: [f64; 3] = xs
            .iter()
            .fold(DVec3::ZERO, |p, x| p + 0.25 * DVec3::from(*x))
            .into();
        let q: [f64; 3] = (DVec3::from(p) + DVec3::from(m.correction(p, &xs, 0.25))).into();
        let on = g(q[0], q[1]);
        assert!((q[2] - on[2]).abs() < 1e-5, "{q:?} vs {on:?}");
        assert!((p[2] - g(p[0], p[1])[2]).abs() > 1e-3);
    }
    /// A one-sided ring on a circular cylinder (a wall's rim vertex, and the vertex one row
    /// above it), 22.5° per cell: the anisotropic conic makes the refitted models exact, so
    /// face-centre and edge-midpoint targets lie on the cylinder to rounding; the one-ring
    /// quadric cannot even be fitted at the rim vertex (only two rows across).
    #[test]
    fn one_sided_height_functions_are_exact_on_cylinders() {
        let (dt, dz) = (std::f64::consts::PI / 8.0, 0.25);
        let g = |i: i32, j: i32| [(i as f64 * dt).cos(), (i as f64 * dt).sin(), j as f64 * dz];
        let flat = VertexModel {
            normal: [1.0, 0.0, 0.0],
            h: [[0.0; 3]; 3],
            weight: 1.0,
        };
        let ring = |row: i32, rows: i32| -> Vec<[f64; 3]> {
            (-2..=2)
                .flat_map(|i| (0..rows).map(move |j| (i, j)))
                .filter(|&(i, j)| (i, j) != (0, row))
                .map(|(i, j)| g(i, j))
                .collect()
        };
        let target = |m: &VertexModel, hm: &HigherModel, xs: &[[f64; 3]]| -> f64 {
            let phi = 1.0 / xs.len() as f64;
            let p: DVec3 = xs.iter().map(|&x| phi * DVec3::from(x)).sum();
            let c = DVec3::from(m.correction(p.into(), xs, phi))
                + hm.correction(p.into(), xs, phi) * DVec3::from(m.normal);
            ((p + c).truncate().length() - 1.0).abs()
        };
        let chord = (g(0, 0)[0] + g(1, 0)[0]) / 2.0;
        let chord_error = 1.0 - chord.hypot((g(0, 0)[1] + g(1, 0)[1]) / 2.0);
        // The rim vertex: three rows, the quadratic remainder.
        let (m, hm) = refine_patch_model(g(0, 0), &flat, &ring(0, 3), 0.3).unwrap();
        let face = [g(0, 0), g(1, 0), g(1, 1), g(0, 1)];
        let edge = [g(0, 0), g(1, 0)];
        for xs in [&face[..], &edge[..]] {
            let e = target(&m, &hm, xs);
            assert!(e < 1e-9, "rim: {e:e} (chord {chord_error:e})");
        }
        // The vertex one row above: a smooth vertex whose ring stops at the rim.
        let (m, hm) = refine_model(3, g(0, 1), &flat, &ring(1, 4), 0.3, Height::ONE_SIDED).unwrap();
        let face = [g(0, 1), g(1, 1), g(1, 2), g(0, 2)];
        let e = target(&m, &hm, &face);
        assert!(e < 1e-9, "row above the rim: {e:e} (chord {chord_error:e})");
        assert!(chord_error > 1e-2);
    }
}
