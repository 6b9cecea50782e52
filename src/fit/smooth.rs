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
//! the tangent plane, or a singular system keep the one-ring quadric.
//!
//! With detected sharp features ([`SmoothTargets::build_with_features`]) the vertices on
//! features take their models per patch and along feature curves instead
//! ([`super::features::FeatureModels`]), so no model averages across a feature; samples inside
//! the mesh use a feature vertex's curve model. The vertices of planar patches (2D: straight
//! chains) take in-plane models from the patch's rim instead of their flat fan model, and in
//! 3D are no sources for the interior vertices.

use super::features::{BoundaryEntity, FeatureModels};
use crate::mesh::features::Features;
use crate::mesh::topology::{HEX_EDGES, HEX_VERTEX_PARAMS, NONE};
use crate::mesh::vec3::{add, cross, dot, norm, sub};
use crate::mesh::{LinearMesh, Topology};
use rayon::prelude::*;
use std::cmp::Reverse;
use std::collections::BinaryHeap;

/// Parameters of the smooth-boundary reconstruction.
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
}

impl Default for SmoothParams {
    fn default() -> Self {
        SmoothParams {
            feature_angle_deg: 30.0,
            decay: 1.0,
            kink_angle_deg: 10.0,
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
        let mut s = 0.0;
        for x in xs {
            let y = sub(*x, p);
            let hy = matvec(&self.h, y);
            s += phi * dot(y, hy);
        }
        self.normal.map(|n| -s * n)
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
}

/// The cubic and quartic part of a vertex's height function over its model's tangent frame
/// (the quadratic part is the [`VertexModel`]'s H, in the same frame).
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct HigherModel {
    /// The vertex the height function is centred on.
    origin: [f64; 3],
    /// Tangent frame (t₂ = 0 in 2D).
    t: [[f64; 3]; 2],
    /// Length scale ℓ of the coefficients: g(ξ, ζ) = ℓ Σ c_i m_i(ξ/ℓ, ζ/ℓ).
    scale: f64,
    /// Coefficients of the monomials u³, u²w, uw², w³, u⁴, u³w, u²w², uw³, w⁴.
    c: [f64; 9],
    /// Scaled curvature κℓ of the circle (2D) or sphere (3D) whose height above its tangent
    /// plane, minus its quadratic part, is added to the polynomial (see [`sphere_height`]).
    kappa: f64,
}

/// Height above its tangent plane of the circle or sphere of curvature `kappa` touching the
/// plane at the origin, at squared distance `r2` from the origin (scaled units), when it has
/// one: κr²/(1 + √(1 − κ²r²)).
fn sphere_height(kappa: f64, r2: f64) -> Option<f64> {
    let d = 1.0 - kappa * kappa * r2;
    (d >= 0.0).then(|| kappa * r2 / (1.0 + d.sqrt()))
}

impl HigherModel {
    fn height(&self, x: [f64; 3]) -> f64 {
        let y = sub(x, self.origin);
        let (u, w) = (
            dot(y, self.t[0]) / self.scale,
            dot(y, self.t[1]) / self.scale,
        );
        let m = &monomials(u, w)[5..];
        let r2 = u * u + w * w;
        // Beyond the sphere's reach (far from the vertex) only its quadratic part is kept.
        let sphere = sphere_height(self.kappa, r2).map_or(0.0, |h| h - 0.5 * self.kappa * r2);
        self.scale * (sphere + m.iter().zip(&self.c).map(|(a, b)| a * b).sum::<f64>())
    }

    /// g(ξ_p) − Σ φ g(ξ_j): the cubic and quartic terms' share of the correction's length
    /// along the normal (the linear terms cancel as for H).
    fn correction(&self, p: [f64; 3], xs: &[[f64; 3]], phi: f64) -> f64 {
        self.height(p) - xs.iter().map(|x| phi * self.height(*x)).sum::<f64>()
    }
}

/// The monomials u, w, u², uw, w², u³, u²w, uw², w³, u⁴, u³w, u²w², uw³, w⁴ of a height fit.
fn monomials(u: f64, w: f64) -> [f64; 14] {
    let (u2, w2) = (u * u, w * w);
    [
        u,
        w,
        u2,
        u * w,
        w2,
        u2 * u,
        u2 * w,
        u * w2,
        w2 * w,
        u2 * u2,
        u2 * u * w,
        u2 * w2,
        u * w2 * w,
        w2 * w2,
    ]
}

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
        let nv = mesh.n_vertices();
        let cos_max = params.feature_angle_deg.to_radians().cos();
        let mut models: Vec<Option<VertexModel>> = vec![None; nv];
        let mut ell = vec![0.0; nv];
        // Boundary fans: facets at each boundary vertex.
        let mut fan: Vec<Vec<u32>> = vec![Vec::new(); nv];
        for &f in &topo.boundary_facets {
            for &v in topo.facet_vertices(f as usize) {
                fan[v as usize].push(f);
            }
        }
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
                    if fan[v].len() != 2 {
                        return;
                    }
                    let other = |f: u32| {
                        let e = topo.edges[f as usize];
                        if e[0] as usize == v { e[1] } else { e[0] }
                    };
                    let (a, b) = (x(other(fan[v][0])), x(other(fan[v][1])));
                    let (ua, ub) = (sub(a, xv), sub(b, xv));
                    let (la, lb) = (norm(ua), norm(ub));
                    if la == 0.0 || lb == 0.0 {
                        return;
                    }
                    *ell = 0.5 * (la + lb);
                    // Turning angle between the edges ≤ 2 × the feature angle.
                    let cos_turn = -dot(ua, ub) / (la * lb);
                    if cos_turn < (2.0 * params.feature_angle_deg.to_radians()).cos() {
                        return;
                    }
                    *model = fit_parabola(xv, a, b).map(|(normal, h)| VertexModel {
                        normal,
                        h,
                        weight: 1.0,
                    });
                } else {
                    if fan[v].len() < 3 {
                        return;
                    }
                    if let Some((m, l)) = fan_model(mesh, topo, v as u32, &fan[v], cos_max) {
                        *ell = l;
                        *model = m;
                    }
                }
            });
        // Second pass: height functions of degree up to four over two rings of boundary
        // vertices, reached through smooth vertices only (so never across a feature).
        let mut higher: Vec<Option<HigherModel>> = vec![None; nv];
        {
            let models_ref = &models;
            let ell_ref = &ell;
            let fan_ref = &fan;
            let refined: Vec<Option<(VertexModel, HigherModel)>> = (0..nv)
                .into_par_iter()
                .with_min_len(1024)
                .map(|v| {
                    let m = models_ref[v]?;
                    let ring = two_ring(mesh, topo, fan_ref, models_ref, v as u32, cos_max);
                    refine_model(mesh.dim, mesh.coords[v], &m, &ring, ell_ref[v])
                })
                .collect();
            for (v, r) in refined.into_iter().enumerate() {
                if let Some((m, h)) = r {
                    models[v] = Some(m);
                    higher[v] = Some(h);
                }
            }
        }
        let smooth_vertices = models.iter().filter(|m| m.is_some()).count();
        let feature_vertices =
            topo.vertex_on_boundary.iter().filter(|&&b| b).count() - smooth_vertices;
        let feature_models =
            features.map(|f| FeatureModels::build(mesh, topo, f, cos_max, params.decay));
        // A 3D planar patch is its own 2D problem (its vertices take in-plane models below):
        // the cells next to it inherit from the curved boundary, not from the plane.
        let in_plane_3d = |v: usize| {
            mesh.dim == 3
                && feature_models
                    .as_ref()
                    .is_some_and(|f| f.in_plane.contains_key(&(v as u32)))
        };

        // Interior vertices inherit the nearest smooth boundary vertex's model (Dijkstra along
        // mesh edges from the smooth boundary vertices, cut off at decay · ℓ).
        let mut blended_vertices = 0;
        if params.decay > 0.0 {
            let mut offsets = vec![0u32; nv + 1];
            for e in &topo.edges {
                offsets[e[0] as usize + 1] += 1;
                offsets[e[1] as usize + 1] += 1;
            }
            for i in 0..nv {
                offsets[i + 1] += offsets[i];
            }
            let mut fill = offsets.clone();
            let mut adj = vec![0u32; offsets[nv] as usize];
            for e in &topo.edges {
                for (a, b) in [(e[0], e[1]), (e[1], e[0])] {
                    adj[fill[a as usize] as usize] = b;
                    fill[a as usize] += 1;
                }
            }
            let mut dist = vec![f64::INFINITY; nv];
            let mut source = vec![NONE; nv];
            let mut heap = BinaryHeap::new();
            for v in 0..nv {
                if models[v].is_some() && !in_plane_3d(v) {
                    dist[v] = 0.0;
                    source[v] = v as u32;
                    heap.push(Reverse((0u64, v as u32)));
                }
            }
            while let Some(Reverse((d_bits, v))) = heap.pop() {
                let d = f64::from_bits(d_bits);
                if d > dist[v as usize] {
                    continue;
                }
                let s = source[v as usize] as usize;
                let cutoff = params.decay * ell[s];
                for &w in &adj[offsets[v as usize] as usize..offsets[v as usize + 1] as usize] {
                    if topo.vertex_on_boundary[w as usize] {
                        continue;
                    }
                    let nd = d + norm(sub(x(w), x(v)));
                    if nd < cutoff && nd < dist[w as usize] {
                        dist[w as usize] = nd;
                        source[w as usize] = s as u32;
                        heap.push(Reverse((nd.to_bits(), w)));
                    }
                }
            }
            for v in 0..nv {
                if !topo.vertex_on_boundary[v] && source[v] != NONE {
                    let s = source[v] as usize;
                    let g = 1.0 - dist[v] / (params.decay * ell[s]);
                    if g > 0.0 {
                        let m = models[s].expect("sources have models");
                        models[v] = Some(VertexModel { weight: g, ..m });
                        higher[v] = higher[s];
                        blended_vertices += 1;
                    }
                }
            }
        }
        if let Some(f) = &feature_models {
            for (&v, m) in &f.in_plane {
                models[v as usize] = Some(*m);
                // The height function was fitted over the plane, not along the in-plane curve.
                higher[v as usize] = None;
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
        }
    }

    /// The model of vertex `v`, if it has one.
    pub fn vertex_model(&self, v: usize) -> Option<&VertexModel> {
        self.models[v].as_ref()
    }

    /// Displacements of the 3^d sample targets of element `e` from the multilinear points
    /// (index 9z + 3y + x of the lattice {0, ½, 1}^d; zero at corners).
    pub fn element_corrections(
        &self,
        mesh: &LinearMesh,
        topo: &Topology,
        e: usize,
    ) -> [[f64; 3]; 27] {
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
        lattice: &[[f64; 3]; 27],
    ) -> [[f64; 3]; 27] {
        let dim = self.dim;
        let n = if dim == 2 { 9 } else { 27 };
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
        let (mut xs, mut ks) = ([[0.0; 3]; 8], [0usize; 8]);
        for (i, slot) in out.iter_mut().enumerate().take(n) {
            let l = [i % 3, (i / 3) % 3, i / 9];
            let m = (0..dim).filter(|&k| l[k] == 1).count();
            if m == 0 {
                continue;
            }
            let mut len = 0;
            for (c, pc) in HEX_VERTEX_PARAMS.iter().enumerate().take(1 << dim) {
                if (0..dim).all(|k| l[k] == 1 || 2 * pc[k] as usize == l[k]) {
                    (xs[len], ks[len]) = (x[c], verts[c] as usize);
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
            let mut delta = [0.0; 3];
            let mut wsum = 0.0;
            for &k in ks {
                let higher = self.models[k].and(self.higher.get(k).copied().flatten());
                let model = self.models[k].as_ref().or_else(|| {
                    let f = self.feature_models.as_ref()?;
                    match at {
                        Some(at) => f.model(k as u32, at),
                        None => f.interior_model(k as u32),
                    }
                });
                if let Some(model) = model {
                    let mut c = model.correction(p, xs, phi);
                    if let Some(hm) = higher {
                        let g = hm.correction(p, xs, phi);
                        c = add(c, model.normal.map(|n| g * n));
                    }
                    let w = phi * model.weight;
                    delta = add(delta, c.map(|ci| w * ci));
                    wsum += phi;
                }
            }
            if on_boundary && wsum > 0.0 {
                delta = delta.map(|d| d / wsum);
            }
            *slot = delta;
        }
        out
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

/// The 3D model at vertex `v` from the boundary faces `faces` around it, with the fan's length
/// scale ℓ; `None` when the fan is degenerate, has fewer than 5 neighbour vertices, or a face
/// normal is more than acos(`cos_max`) from the fan normal (the model is `None` when the
/// quadric fit fails).
pub(super) fn fan_model(
    mesh: &LinearMesh,
    topo: &Topology,
    v: u32,
    faces: &[u32],
    cos_max: f64,
) -> Option<(Option<VertexModel>, f64)> {
    let x = |w: u32| mesh.coords[w as usize];
    let mut area = [0.0; 3];
    let mut normals = Vec::with_capacity(faces.len());
    let mut nb: Vec<u32> = Vec::new();
    let mut total_area = 0.0;
    for &f in faces {
        let q = topo.faces[f as usize];
        let a = cross(sub(x(q[2]), x(q[0])), sub(x(q[3]), x(q[1])));
        area = add(area, a);
        let l = norm(a);
        total_area += 0.5 * l;
        normals.push(a.map(|c| c / l.max(f64::MIN_POSITIVE)));
        nb.extend(q.iter().copied().filter(|&w| w != v));
    }
    nb.sort_unstable();
    nb.dedup();
    let la = norm(area);
    if la == 0.0 || nb.len() < 5 {
        return None;
    }
    let n0 = area.map(|c| c / la);
    if normals.iter().any(|nf| dot(*nf, n0) < cos_max) {
        return None;
    }
    let ell = (total_area / faces.len() as f64).sqrt();
    let pts: Vec<[f64; 3]> = nb.iter().map(|&w| sub(x(w), x(v))).collect();
    let model = fit_quadric(n0, &pts, ell).map(|(normal, h)| VertexModel {
        normal,
        h,
        weight: 1.0,
    });
    Some((model, ell))
}

/// 2D model at x through its boundary neighbours a and b: (normal, H).
pub(super) fn fit_parabola(
    x: [f64; 3],
    a: [f64; 3],
    b: [f64; 3],
) -> Option<([f64; 3], [[f64; 3]; 3])> {
    let (ua, ub) = (sub(a, x), sub(b, x));
    let d = sub(ub, ua);
    let l = norm(d);
    let mut t = d.map(|c| c / l);
    let mut fitted = None;
    for _ in 0..3 {
        let n = [-t[1], t[0], 0.0];
        let (xa, ya, xb, yb) = (dot(ua, t), dot(ua, n), dot(ub, t), dot(ub, n));
        let det = xa * xb * xb - xb * xa * xa;
        if !(xa < 0.0 && xb > 0.0) || det.abs() < 1e-300 {
            return None;
        }
        let c1 = (ya * xb * xb - yb * xa * xa) / det;
        let c2 = (xa * yb - xb * ya) / det;
        if c1.abs() > 1.0 {
            return None;
        }
        fitted = Some((t, c2));
        // Tilt the frame to the parabola's tangent at x and fit again.
        let tn = add(t, n.map(|c| c1 * c));
        let ln = norm(tn);
        t = tn.map(|c| c / ln);
    }
    let (t, c2) = fitted?;
    let n = [-t[1], t[0], 0.0];
    let h = outer(t, t).map(|r| r.map(|c| c2 * c));
    Some((n, h))
}

/// 3D model: least-squares quadric height over the tangent plane of normal n0 through the
/// neighbour offsets `pts` (relative to the vertex); `scale` ~ the edge length.
fn fit_quadric(n0: [f64; 3], pts: &[[f64; 3]], scale: f64) -> Option<([f64; 3], [[f64; 3]; 3])> {
    let mut n = n0;
    let mut q = [0.0; 3];
    let mut frame = tangent_frame(n);
    for _ in 0..3 {
        frame = tangent_frame(n);
        let (t1, t2) = frame;
        // Unknowns (a, b, c, d, e) of η = aξ² + bξζ + cζ² + dξ + eζ in scaled coordinates.
        let mut ata = [[0.0; 5]; 5];
        let mut atb = [0.0; 5];
        for p in pts {
            let (u, v, h) = (dot(*p, t1) / scale, dot(*p, t2) / scale, dot(*p, n) / scale);
            let row = [u * u, u * v, v * v, u, v];
            for i in 0..5 {
                for j in 0..5 {
                    ata[i][j] += row[i] * row[j];
                }
                atb[i] += row[i] * h;
            }
        }
        let s = solve5(ata, atb)?;
        // Back to unscaled: η = (a/scale) ξ² + …, slopes unchanged.
        q = [s[0] / scale, s[1] / scale, s[2] / scale];
        let (d, e) = (s[3], s[4]);
        if d.hypot(e) > 1.0 {
            return None;
        }
        let nn = sub(n, add(t1.map(|c| d * c), t2.map(|c| e * c)));
        let l = norm(nn);
        n = nn.map(|c| c / l);
    }
    let (t1, t2) = frame;
    let mut h = [[0.0; 3]; 3];
    let parts = [
        (outer(t1, t1), q[0]),
        (sym_outer(t1, t2), 0.5 * q[1]),
        (outer(t2, t2), q[2]),
    ];
    for (m, w) in parts {
        for i in 0..3 {
            for j in 0..3 {
                h[i][j] += w * m[i][j];
            }
        }
    }
    // The quadric was fitted in the frame before the last tilt; use that frame's normal so H
    // and n belong together (H n = 0).
    Some((cross(t1, t2), h))
}

/// The boundary vertices within two rings of the smooth boundary vertex `v` (2D: along the
/// boundary chain; 3D: over boundary faces), the second ring reached only through vertices that
/// have a model, so no ring crosses a sharp feature. `v` itself is not included.
fn two_ring(
    mesh: &LinearMesh,
    topo: &Topology,
    fan: &[Vec<u32>],
    models: &[Option<VertexModel>],
    v: u32,
    cos_max: f64,
) -> Vec<[f64; 3]> {
    // A model-carrying vertex next to a feature (a rim vertex whose fan model spans a gentle
    // crease) would bring in the facets across it: in 3D the second ring keeps only facets
    // within the feature angle of v's normal.
    let n_v = models[v as usize].map(|m| m.normal);
    let facing = |f: usize| -> bool {
        let (Some(n), 3) = (n_v, mesh.dim) else {
            return true;
        };
        let fv = topo.facet_vertices(f);
        if fv.len() < 4 {
            return true;
        }
        let c = |i: usize| mesh.coords[fv[i] as usize];
        let d1 = sub(c(2), c(0));
        let d2 = sub(c(3), c(1));
        let nf = [
            d1[1] * d2[2] - d1[2] * d2[1],
            d1[2] * d2[0] - d1[0] * d2[2],
            d1[0] * d2[1] - d1[1] * d2[0],
        ];
        let l = norm(nf);
        l > 0.0 && dot(nf, n).abs() >= cos_max * l
    };
    let mut ring: Vec<u32> = Vec::new();
    let mut first: Vec<u32> = Vec::new();
    for &f in &fan[v as usize] {
        first.extend(
            topo.facet_vertices(f as usize)
                .iter()
                .copied()
                .filter(|&w| w != v),
        );
    }
    first.sort_unstable();
    first.dedup();
    // Next to a feature (a first-ring vertex without a smooth model) the height function's
    // ring would be one-sided and cut by the feature: keep the one-ring quadric there.
    if first.iter().any(|&u| models[u as usize].is_none()) {
        return Vec::new();
    }
    ring.extend(&first);
    for &u in &first {
        if models[u as usize].is_none() {
            continue;
        }
        for &f in fan[u as usize].iter().filter(|&&f| facing(f as usize)) {
            ring.extend(
                topo.facet_vertices(f as usize)
                    .iter()
                    .copied()
                    .filter(|&w| w != v),
            );
        }
    }
    ring.sort_unstable();
    ring.dedup();
    ring.iter().map(|&w| mesh.coords[w as usize]).collect()
}

/// Refit the model `m` of the vertex at `x` as a height function of degree up to four over its
/// two-ring points `pts` (relative scale `ell`): 2D u, u², u³, u⁴ through up to four points;
/// 3D all 14 monomials of degree 1–4 by least squares over at least 20 points, or those of
/// degree 1–3 over at least 12. The frame is re-tilted by the linear terms and the fit
/// repeated, as for the quadric. `None` (keep `m`) with too few points, where the points are
/// not a graph over the tangent plane (slope above 1), or when the system is singular.
fn refine_model(
    dim: usize,
    x: [f64; 3],
    m: &VertexModel,
    pts: &[[f64; 3]],
    ell: f64,
) -> Option<(VertexModel, HigherModel)> {
    if !(ell > 0.0) {
        return None;
    }
    const CUBIC: &[usize] = &[0, 1, 2, 3, 4, 5, 6, 7, 8];
    const QUARTIC: &[usize] = &[0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13];
    let used: &[usize] = if dim == 2 {
        match pts.len() {
            0..=2 => return None,
            3 => &[0, 2, 5],
            _ => &[0, 2, 5, 9],
        }
    } else if pts.len() >= 20 {
        QUARTIC
    } else if pts.len() >= 12 {
        CUBIC
    } else {
        return None;
    };
    // A ring with too few distinct rows in one direction (an extruded wall a few cells
    // across) leaves the quartic undetermined: fall back to the cubic before the quadric.
    if used.len() == QUARTIC.len() {
        if let Some(r) = refine_with(dim, x, m, pts, ell, QUARTIC) {
            return Some(r);
        }
        return refine_with(dim, x, m, pts, ell, CUBIC);
    }
    refine_with(dim, x, m, pts, ell, used)
}

/// [`refine_model`] with the monomials `used`.
fn refine_with(
    dim: usize,
    x: [f64; 3],
    m: &VertexModel,
    pts: &[[f64; 3]],
    ell: f64,
    used: &[usize],
) -> Option<(VertexModel, HigherModel)> {
    let frame_of = |n: [f64; 3]| -> ([f64; 3], [f64; 3]) {
        if dim == 2 {
            ([n[1], -n[0], 0.0], [0.0; 3])
        } else {
            tangent_frame(n)
        }
    };
    let mut n = m.normal;
    // Scaled mean curvature of the quadric: the sphere (circle) part of the height function,
    // which makes the model exact on spheres and circles however coarse the ring.
    let trace = m.h[0][0] + m.h[1][1] + m.h[2][2];
    let mut kappa = 2.0 * trace / (dim - 1) as f64 * ell;
    let mut fitted = None;
    for _ in 0..4 {
        let (t1, t2) = frame_of(n);
        let k = used.len();
        let mut ata = vec![vec![0.0; k]; k];
        let mut atb = vec![0.0; k];
        for p in pts {
            let y = sub(*p, x);
            let (u, w, h) = (dot(y, t1) / ell, dot(y, t2) / ell, dot(y, n) / ell);
            if h.abs() > u.hypot(w) {
                return None;
            }
            if sphere_height(kappa, u * u + w * w).is_none() {
                kappa = 0.0;
            }
        }
        for p in pts {
            let y = sub(*p, x);
            let (u, w) = (dot(y, t1) / ell, dot(y, t2) / ell);
            let h = dot(y, n) / ell - sphere_height(kappa, u * u + w * w).unwrap_or(0.0);
            let all = monomials(u, w);
            for i in 0..k {
                for j in 0..k {
                    ata[i][j] += all[used[i]] * all[used[j]];
                }
                atb[i] += all[used[i]] * h;
            }
        }
        let sol = solve_n(ata, atb)?;
        let mut c = [0.0; 14];
        for (i, &u) in used.iter().enumerate() {
            c[u] = sol[i];
        }
        if c[0].hypot(c[1]) > 1.0 {
            return None;
        }
        fitted = Some((n, t1, t2, c, kappa));
        // Move the isotropic part of the quadratic remainder into the sphere.
        kappa += 2.0 * (c[2] + c[4]) / (dim - 1) as f64;
        let nn = sub(n, add(t1.map(|v| c[0] * v), t2.map(|v| c[1] * v)));
        let l = norm(nn);
        n = nn.map(|v| v / l);
    }
    // The polynomial belongs to the frame it was fitted in (before the last tilt).
    let (n, t1, t2, c, kappa) = fitted?;
    // Quadratic part: the sphere's κr²/2 and the polynomial's.
    let q = [
        (c[2] + 0.5 * kappa) / ell,
        c[3] / ell,
        (c[4] + if dim == 2 { 0.0 } else { 0.5 * kappa }) / ell,
    ];
    let mut h = [[0.0; 3]; 3];
    for (mat, w) in [
        (outer(t1, t1), q[0]),
        (sym_outer(t1, t2), 0.5 * q[1]),
        (outer(t2, t2), q[2]),
    ] {
        for i in 0..3 {
            for j in 0..3 {
                h[i][j] += w * mat[i][j];
            }
        }
    }
    let mut hc = [0.0; 9];
    hc.copy_from_slice(&c[5..]);
    Some((
        VertexModel {
            normal: n,
            h,
            weight: m.weight,
        },
        HigherModel {
            origin: x,
            t: [t1, t2],
            scale: ell,
            c: hc,
            kappa,
        },
    ))
}

/// Gaussian elimination with partial pivoting; `None` when nearly singular.
fn solve_n(mut a: Vec<Vec<f64>>, mut b: Vec<f64>) -> Option<Vec<f64>> {
    let n = b.len();
    let scale = (0..n).map(|i| a[i][i].abs()).fold(0.0, f64::max);
    if !(scale > 0.0) {
        return None;
    }
    for c in 0..n {
        let p = (c..n).max_by(|&i, &j| a[i][c].abs().total_cmp(&a[j][c].abs()))?;
        // Relative to the unit-scaled monomials' Gram matrix: a smaller pivot means a
        // direction the points do not determine, whose coefficient would be noise.
        if !(a[p][c].abs() > 1e-8 * scale) {
            return None;
        }
        a.swap(c, p);
        b.swap(c, p);
        for r in c + 1..n {
            let f = a[r][c] / a[c][c];
            for k in c..n {
                a[r][k] -= f * a[c][k];
            }
            b[r] -= f * b[c];
        }
    }
    let mut x = vec![0.0; n];
    for r in (0..n).rev() {
        let mut s = b[r];
        for k in r + 1..n {
            s -= a[r][k] * x[k];
        }
        x[r] = s / a[r][r];
    }
    Some(x)
}

fn tangent_frame(n: [f64; 3]) -> ([f64; 3], [f64; 3]) {
    let a = if n[0].abs() < 0.6 {
        [1.0, 0.0, 0.0]
    } else {
        [0.0, 1.0, 0.0]
    };
    let t1 = cross(n, a);
    let l = norm(t1);
    let t1 = t1.map(|c| c / l);
    (t1, cross(n, t1))
}

/// Gaussian elimination with partial pivoting on a 5×5 system; None when nearly singular.
fn solve5(mut a: [[f64; 5]; 5], mut b: [f64; 5]) -> Option<[f64; 5]> {
    let scale = (0..5).map(|i| a[i][i].abs()).fold(0.0, f64::max);
    if scale == 0.0 {
        return None;
    }
    for c in 0..5 {
        let p = (c..5).max_by(|&i, &j| a[i][c].abs().total_cmp(&a[j][c].abs()))?;
        if a[p][c].abs() < 1e-9 * scale {
            return None;
        }
        a.swap(c, p);
        b.swap(c, p);
        for r in c + 1..5 {
            let f = a[r][c] / a[c][c];
            for k in c..5 {
                a[r][k] -= f * a[c][k];
            }
            b[r] -= f * b[c];
        }
    }
    let mut x = [0.0; 5];
    for r in (0..5).rev() {
        let mut s = b[r];
        for k in r + 1..5 {
            s -= a[r][k] * x[k];
        }
        x[r] = s / a[r][r];
    }
    Some(x)
}

fn outer(a: [f64; 3], b: [f64; 3]) -> [[f64; 3]; 3] {
    a.map(|ai| b.map(|bj| ai * bj))
}
fn sym_outer(a: [f64; 3], b: [f64; 3]) -> [[f64; 3]; 3] {
    let (m, n) = (outer(a, b), outer(b, a));
    std::array::from_fn(|i| std::array::from_fn(|j| m[i][j] + n[i][j]))
}
fn matvec(m: &[[f64; 3]; 3], v: [f64; 3]) -> [f64; 3] {
    m.map(|r| dot(r, v))
}

#[cfg(test)]
mod tests {
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
            let q = add(p, m.correction(p, &[a, b], 0.5));
            errs.push(((norm(q) - 1.0).abs(), (norm(p) - 1.0).abs()));
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
            pts.push(sub(g(u, v), x0));
        }
        let n0 = [0.0, 0.0, 1.0];
        let (n, h) = fit_quadric(n0, &pts, 0.1).unwrap();
        let m = VertexModel {
            normal: n,
            h,
            weight: 1.0,
        };
        let xs = [g(0.0, 0.0), g(0.1, 0.0), g(0.1, 0.1), g(0.0, 0.1)];
        let mut p = [0.0; 3];
        for x in xs {
            p = add(p, x.map(|c| 0.25 * c));
        }
        let q = add(p, m.correction(p, &xs, 0.25));
        let on = g(q[0], q[1]);
        assert!((q[2] - on[2]).abs() < 1e-5, "{q:?} vs {on:?}");
        assert!((p[2] - g(p[0], p[1])[2]).abs() > 1e-3);
    }
}
