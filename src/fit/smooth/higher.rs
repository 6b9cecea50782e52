//! Two-ring height functions of the smooth boundary vertices (see the parent module's docs):
//! the boundary vertices within two rings of a smooth vertex ([`two_ring`]), the least-squares
//! refit of its model as a conic part plus monomials of degree 1–4 ([`refine_model`]), and the
//! cubic and quartic remainder each sample correction adds ([`HigherModel`]).
//!
//! The conic part is the height of the quadric c η² − 2η + q(u, w) = 0 over the tangent plane,
//! q = a u² + b uw + d w² the fitted curvature form (principal curvatures κ₁, κ₂) and
//! c = (κ₁³ + κ₂³)/(κ₁² + κ₂²): the sphere when κ₁ = κ₂, the circular cylinder when one of them
//! is 0, and on any surface a term the monomials correct from the fourth order on. A sphere of
//! the mean curvature alone (c = κ, q = κ(u² + w²)) is exact on spheres only: on a cylinder it
//! leaves quartic terms in the axial direction that a one-sided ring (a wall next to a rim)
//! cannot cancel.
//!
//! Input: the one-ring models of [`super::one_ring`]. Output: per vertex, a refined
//! [`VertexModel`] (same weight, H and normal of the height function's quadratic part) and its
//! [`HigherModel`], or `None` where the one-ring model is kept.

use super::VertexModel;
use super::one_ring::{outer, sym_outer, tangent_frame};
use crate::math::linalg::{DVec3, unit};
use crate::mesh::periodic::Rigid;
use crate::mesh::{LinearMesh, Topology};

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
    /// Scaled curvature form (a, b, d) of the conic whose height above its tangent plane,
    /// minus its quadratic part, is added to the polynomial (see [`conic_height`]).
    form: [f64; 3],
    /// Coarse curves ([`conic_fit`]): the scaled coefficients (A, B, C) of the conic
    /// A u² + B uη + C η² − 2η = 0 through the vertex and its four ring points, which then
    /// replaces the circle (`form` and `c` zero), and the span [u₋, u₊] of its two neighbours
    /// along the curve, beyond which it goes on along its tangent ([`conic_excess`]).
    conic: Option<([f64; 3], [f64; 2])>,
}

/// Height above its tangent plane of the conic with curvature form q = a u² + b uw + d w²
/// (`form` = (a, b, d), scaled units) touching the plane at the origin, at (u, w), when it has
/// one: q/(1 + √(1 − c q)) with c = (κ₁³ + κ₂³)/(κ₁² + κ₂²) from the form's eigenvalues κ
/// (the circle or sphere κr²/(1 + √(1 − κ²r²)) when a = d = κ, b = 0).
fn conic_height(form: [f64; 3], u: f64, w: f64) -> Option<f64> {
    let [a, b, d] = form;
    let q = a * u * u + b * u * w + d * w * w;
    let (tr, det) = (a + d, a * d - 0.25 * b * b);
    let squares = tr * tr - 2.0 * det;
    let c = if squares > 0.0 {
        tr * (tr * tr - 3.0 * det) / squares
    } else {
        0.0
    };
    let disc = 1.0 - c * q;
    (disc >= 0.0).then(|| q / (1.0 + disc.sqrt()))
}

/// The curvature form of the 3×3 tensor `k` in the tangent frame (t₁, t₂).
fn form_in(k: &[[f64; 3]; 3], t1: DVec3, t2: DVec3) -> [f64; 3] {
    let kk = |a: DVec3, b: DVec3| -> f64 {
        (0..3)
            .map(|i| a[i] * (0..3).map(|j| k[i][j] * b[j]).sum::<f64>())
            .sum()
    };
    [kk(t1, t1), 2.0 * kk(t1, t2), kk(t2, t2)]
}

impl HigherModel {
    /// Values in a record ([`HigherModel::write`], [`HigherModel::read`]).
    pub(crate) const LEN: usize = 28;

    /// Writes the model into `out` (`LEN` values), to travel between ranks.
    pub(crate) fn write(&self, out: &mut [f64]) {
        let (conic, span) = self.conic.unwrap_or(([0.0; 3], [0.0; 2]));
        let flag = f64::from(u8::from(self.conic.is_some()));
        let parts: [&[f64]; 9] = [
            &self.origin,
            &self.t[0],
            &self.t[1],
            &[self.scale],
            &self.c,
            &self.form,
            &[flag],
            &conic,
            &span,
        ];
        for (o, x) in out.iter_mut().zip(parts.into_iter().flatten()) {
            *o = *x;
        }
    }

    /// The model [`HigherModel::write`] wrote into `r`.
    pub(crate) fn read(r: &[f64]) -> HigherModel {
        let a3 = |i: usize| [r[i], r[i + 1], r[i + 2]];
        HigherModel {
            origin: a3(0),
            t: [a3(3), a3(6)],
            scale: r[9],
            c: std::array::from_fn(|k| r[10 + k]),
            form: a3(19),
            conic: (r[22] != 0.0).then(|| (a3(23), [r[26], r[27]])),
        }
    }

    /// The height function seen through the rigid map `t` (a periodic seam's): its origin
    /// moved and its tangent frame turned by `t`, the same function of the moved points.
    pub(crate) fn carried(&self, t: &Rigid) -> HigherModel {
        let turn = |a: [f64; 3]| {
            let r = &t.rotation;
            std::array::from_fn(|i| r[i][0] * a[0] + r[i][1] * a[1] + r[i][2] * a[2])
        };
        HigherModel {
            origin: t.apply(self.origin),
            t: self.t.map(turn),
            ..*self
        }
    }

    fn height(&self, x: [f64; 3]) -> f64 {
        let y = DVec3::from(x) - DVec3::from(self.origin);
        let (u, w) = (
            y.dot(self.t[0].into()) / self.scale,
            y.dot(self.t[1].into()) / self.scale,
        );
        let m = &monomials(u, w)[5..];
        let [a, b, d] = self.form;
        let q = a * u * u + b * u * w + d * w * w;
        // Beyond the circle's or sphere's reach (far from the vertex) only its quadratic part
        // is kept; a coarse curve's conic goes on along its tangent beyond its neighbours.
        let conic = match self.conic {
            Some((abc, span)) => conic_excess(abc, span, u),
            None => conic_height(self.form, u, w).map_or(0.0, |h| h - 0.5 * q),
        };
        self.scale * (conic + m.iter().zip(&self.c).map(|(a, b)| a * b).sum::<f64>())
    }

    /// g(ξ_p) − Σ φ g(ξ_j): the cubic and quartic terms' share of the correction's length
    /// along the normal (the linear terms cancel as for H).
    pub(in crate::fit) fn correction(&self, p: [f64; 3], xs: &[[f64; 3]], phi: f64) -> f64 {
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

/// Reusable buffers of [`two_ring`] (one per worker, so the rings allocate nothing).
#[derive(Default)]
pub(in crate::fit) struct RingScratch {
    /// The first ring of the last [`two_ring`].
    pub(super) first: Vec<u32>,
    ring: Vec<u32>,
}

impl RingScratch {
    /// Whether the first ring of the last [`two_ring`] reached a vertex without a smooth
    /// model (a feature), so that its ring is one-sided.
    pub(super) fn one_sided(&self, models: &[Option<VertexModel>]) -> bool {
        self.first.iter().any(|&u| models[u as usize].is_none())
    }
}

/// The boundary vertices within two rings of the smooth boundary vertex `v` (2D: along the
/// boundary chain; 3D: over boundary faces), the second ring reached only through vertices that
/// have a model, so no ring crosses a sharp feature. `v` itself is not included.
pub(super) fn two_ring(
    mesh: &LinearMesh,
    topo: &Topology,
    fan: &[Vec<u32>],
    models: &[Option<VertexModel>],
    v: u32,
    cos_max: f64,
    scratch: &mut RingScratch,
) -> Vec<[f64; 3]> {
    two_ring_from(
        mesh,
        topo,
        &fan[v as usize],
        fan,
        models,
        v,
        cos_max,
        scratch,
    )
}

/// [`two_ring`] whose first ring is that of the facets `own` at `v` (at a feature vertex: the
/// facets of one patch), the second reached through the smooth vertices among them.
#[allow(clippy::too_many_arguments)]
pub(in crate::fit) fn two_ring_from(
    mesh: &LinearMesh,
    topo: &Topology,
    own: &[u32],
    fan: &[Vec<u32>],
    models: &[Option<VertexModel>],
    v: u32,
    cos_max: f64,
    scratch: &mut RingScratch,
) -> Vec<[f64; 3]> {
    // A model-carrying vertex next to a feature (a rim vertex whose fan model spans a gentle
    // crease) would bring in the facets across it: in 3D the second ring keeps only facets
    // within the feature angle of the normal of the first-ring vertex u they are reached
    // through. Against u's normal, not v's: on a coarse smooth surface (45° between facets)
    // the second ring's facets turn from v's normal by more than the feature angle, but from
    // u's only by half a facet's turning, as on any smooth surface.
    let facing = |f: usize, u: u32| -> bool {
        let (Some(n), 3) = (models[u as usize].map(|m| m.normal), mesh.dim) else {
            return true;
        };
        let fv = topo.facet_vertices(f);
        if fv.len() < 4 {
            return true;
        }
        let c = |i: usize| DVec3::from(mesh.coords[fv[i] as usize]);
        let nf = (c(2) - c(0)).cross(c(3) - c(1));
        let l = nf.length();
        l > 0.0 && nf.dot(n.into()).abs() >= cos_max * l
    };
    let RingScratch { first, ring } = scratch;
    first.clear();
    ring.clear();
    for &f in own {
        first.extend(
            topo.facet_vertices(f as usize)
                .iter()
                .copied()
                .filter(|&w| w != v),
        );
    }
    first.sort_unstable();
    first.dedup();
    // Next to a feature (a first-ring vertex without a smooth model) the ring is one-sided:
    // the feature's vertices are points of this side's surface, but nothing beyond them is
    // reached. The conic part keeps such a fit exact on cylinders (a wall next to a rim).
    ring.extend_from_slice(first);
    for &u in first.iter() {
        if models[u as usize].is_none() {
            continue;
        }
        for &f in fan[u as usize].iter().filter(|&&f| facing(f as usize, u)) {
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

/// How a height function is fitted: in which plane a curve (`dim` 2) lies, and which conic.
#[derive(Clone, Copy, Debug)]
pub(in crate::fit) struct Height {
    /// Unit normal of the plane of a curve: the xy plane of a 2D mesh, a feature curve's own
    /// plane in 3D (its tangent is n × binormal). Unused for surfaces.
    pub binormal: [f64; 3],
    /// The conic part follows the fitted curvature form (exact on cylinders) instead of the
    /// sphere of its mean curvature (whose quartic terms the monomials correct best over a
    /// ring around the vertex, but not over a one-sided one).
    pub anisotropic: bool,
}

impl Height {
    /// A 2D mesh's boundary, or a surface over a ring around the vertex.
    pub const CENTRED: Height = Height {
        binormal: [0.0, 0.0, 1.0],
        anisotropic: false,
    };
    /// A surface over a ring on one side of the vertex (next to or on a feature).
    pub const ONE_SIDED: Height = Height {
        binormal: [0.0, 0.0, 1.0],
        anisotropic: true,
    };
}

/// Refit the model `m` of the vertex at `x` as a height function of degree up to four over its
/// two-ring points `pts` (relative scale `ell`): 2D u, u², u³, u⁴ through up to four points;
/// 3D all 14 monomials of degree 1–4 by least squares over at least 20 points, or those of
/// degree 1–3 over at least 12. The frame is re-tilted by the linear terms and the fit
/// repeated, as for the quadric. `None` (keep `m`) with too few points, where the points are
/// not a graph over the tangent plane (slope above 1), or when the system is singular.
pub(in crate::fit) fn refine_model(
    dim: usize,
    x: [f64; 3],
    m: &VertexModel,
    pts: &[[f64; 3]],
    ell: f64,
    how: Height,
) -> Option<(VertexModel, HigherModel)> {
    if !(ell > 0.0) {
        return None;
    }
    if dim == 2
        && let Some(r) = coarse_conic_model(x.into(), m, pts, ell, how.binormal.into())
    {
        return Some(r);
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
        if let Some(r) = refine_with(dim, x, m, pts, ell, QUARTIC, how) {
            return Some(r);
        }
        return refine_with(dim, x, m, pts, ell, CUBIC, how);
    }
    refine_with(dim, x, m, pts, ell, used, how)
}

/// [`refine_model`] for a feature vertex's patch (a one-sided ring, anisotropic conic), whose
/// ring may have only three rows across the feature (a wall's rim vertex): where the cubic is
/// not determined, the conic plus a quadratic remainder over at least eight points.
pub(in crate::fit) fn refine_patch_model(
    x: [f64; 3],
    m: &VertexModel,
    pts: &[[f64; 3]],
    ell: f64,
) -> Option<(VertexModel, HigherModel)> {
    const QUADRATIC: &[usize] = &[0, 1, 2, 3, 4];
    let how = Height::ONE_SIDED;
    refine_model(3, x, m, pts, ell, how).or_else(|| {
        (pts.len() >= 8 && ell > 0.0)
            .then(|| refine_with(3, x, m, pts, ell, QUADRATIC, how))
            .flatten()
    })
}

/// Most refit rounds with the anisotropic conic (see [`refine_with`]).
const ANISOTROPIC_ROUNDS: usize = 64;

/// Most monomials a height fit uses (all of degree 1–4 in 3D).
const MAX_TERMS: usize = 14;

/// The normal equations AᵀA c = Aᵀb of a height fit over at most [`MAX_TERMS`] monomials.
type Normal = ([[f64; MAX_TERMS]; MAX_TERMS], [f64; MAX_TERMS]);

/// [`refine_model`] with the monomials `used`.
fn refine_with(
    dim: usize,
    x: [f64; 3],
    m: &VertexModel,
    pts: &[[f64; 3]],
    ell: f64,
    used: &[usize],
    how: Height,
) -> Option<(VertexModel, HigherModel)> {
    let binormal = DVec3::from(how.binormal);
    // The form of the circle (2D) or sphere (3D) of scaled curvature κ.
    let sphere = |kappa: f64| -> [f64; 3] {
        if dim == 2 {
            [kappa, 0.0, 0.0]
        } else {
            [kappa, 0.0, kappa]
        }
    };
    let frame_of = |n: DVec3| -> (DVec3, DVec3) {
        if dim == 2 {
            (n.cross(binormal), DVec3::ZERO)
        } else {
            let (t1, t2) = tangent_frame(n.into());
            (t1.into(), t2.into())
        }
    };
    let x = DVec3::from(x);
    // The points relative to the vertex, computed once for the four frame updates.
    let ys: Vec<DVec3> = pts.iter().map(|&p| DVec3::from(p) - x).collect();
    let mut n = DVec3::from(m.normal);
    // The conic part of the height function, which makes the model exact on circles and
    // spheres (and, anisotropic, circular cylinders) however coarse the ring: isotropic, the
    // scaled mean curvature κ of the quadric; anisotropic, its scaled curvature tensor 2ℓH,
    // kept in world coordinates (the tangent frame of a tilted normal may turn about it).
    let trace = m.h[0][0] + m.h[1][1] + m.h[2][2];
    let mut kappa = 2.0 * trace / (dim - 1) as f64 * ell;
    let mut k3 = m.h.map(|r| r.map(|v| 2.0 * ell * v));
    let mut fitted = None;
    let k = used.len();
    let mut uwh = vec![[0.0; 3]; ys.len()];

    // Over a one-sided ring the tilt and the conic's curvature trade off across the ring's
    // rows and the anisotropic rounds converge slowly (a coarse cylinder's rim: 30 rounds to
    // 1e-8 of the tilt): they run until the linear and quadratic remainders vanish.
    let rounds = if how.anisotropic {
        ANISOTROPIC_ROUNDS
    } else {
        4
    };
    for _ in 0..rounds {
        let (t1, t2) = frame_of(n);
        let mut form = if how.anisotropic {
            form_in(&k3, t1, t2)
        } else {
            sphere(kappa)
        };
        for (y, q) in ys.iter().zip(uwh.iter_mut()) {
            let (u, w, h) = (y.dot(t1) / ell, y.dot(t2) / ell, y.dot(n) / ell);
            if steeper(h, u, w) {
                return None;
            }
            if conic_height(form, u, w).is_none() {
                form = [0.0; 3];
                kappa = 0.0;
            }
            *q = [u, w, h];
        }
        let (ata, atb) = normal_equations(&uwh, form, used);
        let sol = solve_n(ata, atb, k)?;
        let mut c = [0.0; MAX_TERMS];
        for (i, &u) in used.iter().enumerate() {
            c[u] = sol[i];
        }
        if c[0].hypot(c[1]) > 1.0 {
            return None;
        }
        fitted = Some((n, t1, t2, c, form));
        if how.anisotropic && c[..5].iter().all(|r| r.abs() < 1e-13) {
            break;
        }
        // Move the quadratic remainder into the conic (q/2 is its quadratic part): all of it,
        // or its isotropic part into the sphere.
        n = unit(n - (c[0] * t1 + c[1] * t2));
        if !how.anisotropic {
            kappa += 2.0 * (c[2] + c[4]) / (dim - 1) as f64;
            continue;
        }
        let next = [
            form[0] + 2.0 * c[2],
            form[1] + 2.0 * c[3],
            form[2] + 2.0 * c[4],
        ];
        k3 = [[0.0; 3]; 3];
        for (mat, w) in [
            (outer(t1.into(), t1.into()), next[0]),
            (sym_outer(t1.into(), t2.into()), 0.5 * next[1]),
            (outer(t2.into(), t2.into()), next[2]),
        ] {
            for i in 0..3 {
                for j in 0..3 {
                    k3[i][j] += w * mat[i][j];
                }
            }
        }
    }
    // The polynomial belongs to the frame it was fitted in (before the last tilt).
    let (n, t1, t2, c, form) = fitted?;
    let (t1, t2): ([f64; 3], [f64; 3]) = (t1.into(), t2.into());
    // Quadratic part: the conic's q/2 and the polynomial's.
    let q = [
        (c[2] + 0.5 * form[0]) / ell,
        (c[3] + 0.5 * form[1]) / ell,
        (c[4] + 0.5 * form[2]) / ell,
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
            normal: n.into(),
            h,
            weight: m.weight,
        },
        HigherModel {
            origin: x.into(),
            t: [t1, t2],
            scale: ell,
            c: hc,
            form,
            conic: None,
        },
    ))
}

/// Height η(u) through the origin of the conic A u² + B uη + C η² − 2η = 0 (`abc`), on the
/// branch tangent to the u axis there; `None` beyond that branch's reach.
fn curve_conic_height([a, b, c]: [f64; 3], u: f64) -> Option<f64> {
    let p = 2.0 - b * u;
    let disc = p * p - 4.0 * a * c * u * u;
    (p > 0.0 && disc >= 0.0).then(|| 2.0 * a * u * u / (p + disc.sqrt()))
}

/// The conic's height above its tangent minus its quadratic part, η(u) − A u²/2
/// ([`curve_conic_height`]), inside `span` (its neighbours along the curve, where the
/// boundary's own samples lie), and beyond it the tangent line of that difference at the
/// span's end (C¹, so the samples' corrections, which a linear term does not change, keep no
/// conic term there). Offset points far off the curve (a boundary layer's outer cells, which
/// inherit the model) reach tangent coordinates near the end of the conic's branch, where
/// η(u) turns vertical: at the 41° tip of an ellipse O-grid a cell 0.028 off the wall, 0.7 of
/// the tip's radius of curvature, took η's second differences of 1.2× its own height (its
/// target map's Jacobian ratio fell to 0.75× its straight ratio, the certified blend held it
/// at the straight elevation, and the thin cells below with it back to the wall), and the
/// next row left the branch, where the term jumped to zero.
fn conic_excess(abc: [f64; 3], [lo, hi]: [f64; 2], u: f64) -> f64 {
    let [a, b, c] = abc;
    let uc = u.clamp(lo, hi);
    let Some(h) = curve_conic_height(abc, uc) else {
        return 0.0;
    };
    // dη/du on the conic: −F_u / F_η, F = A u² + B uη + C η² − 2η (F_η = −2 at the origin).
    let f_h = b * uc + 2.0 * c * h - 2.0;
    let slope = if f_h < 0.0 {
        -(2.0 * a * uc + b * h) / f_h
    } else {
        0.0
    };
    h - 0.5 * a * uc * uc + (slope - a * uc) * (u - uc)
}

/// A plane curve turns by more than this (degrees) between a vertex's tangent and the chord to
/// a ring point for [`conic_fit`] to replace the circle-plus-polynomial height function.
const CONIC_SLOPE_DEG: f64 = 15.0;

/// The conic through the origin `x` of a plane curve (plane normal `binormal`) and its four
/// ring points `pts` (scale `ell`, approximate normal `n0`): its unit normal at `x` (oriented
/// along `n0`) and its coefficients (A, B, C) in the frame of that normal, in units of `ell`.
/// Five points fix a conic, so the fit is exact on circles and ellipses however coarse the
/// sampling (an ellipse's tip of four cells, where the circle plus cubic and quartic terms is
/// off by 17 % of the chord's sagitta). `None` when the points are not four, the system is
/// singular, or the conic's branch through `x` holds no ring point on one of its sides.
pub(super) fn conic_fit(
    x: DVec3,
    n0: DVec3,
    binormal: DVec3,
    pts: &[DVec3],
    ell: f64,
) -> Option<(DVec3, [f64; 3])> {
    if pts.len() != 4 || !(ell > 0.0) {
        return None;
    }
    let t0 = n0.cross(binormal);
    let uh: Vec<(f64, f64)> = pts
        .iter()
        .map(|&p| ((p - x).dot(t0) / ell, (p - x).dot(n0) / ell))
        .collect();
    // A u² + B uη + C η² + D u = 2η at each point.
    let (mut a, mut r) = ([[0.0; MAX_TERMS]; MAX_TERMS], [0.0; MAX_TERMS]);
    for (i, &(u, h)) in uh.iter().enumerate() {
        a[i][..4].copy_from_slice(&[u * u, u * h, h * h, u]);
        r[i] = 2.0 * h;
    }
    let s = solve_n(a, r, 4)?;
    let (qa, qb, qc, qd) = (s[0], s[1], s[2], s[3]);
    // The gradient at the origin is (D, −2): the normal, and the frame turned onto it.
    let n = unit(2.0 * n0 - qd * t0);
    let t = n.cross(binormal);
    // Old coordinates from new ones: u = r11 u' + r12 η', η = r21 u' + r22 η'.
    let (r11, r12, r21, r22) = (t.dot(t0), n.dot(t0), t.dot(n0), n.dot(n0));
    let quad = |x1: f64, y1: f64, x2: f64, y2: f64| {
        qa * x1 * x2 + 0.5 * qb * (x1 * y2 + y1 * x2) + qc * y1 * y2
    };
    let lin_h = r12 * qd - 2.0 * r22;
    if !(lin_h < 0.0) {
        return None;
    }
    let k = -2.0 / lin_h;
    let abc = [
        k * quad(r11, r21, r11, r21),
        2.0 * k * quad(r11, r21, r12, r22),
        k * quad(r12, r22, r12, r22),
    ];
    // Ring points on the branch through the vertex on both sides of it (its neighbours,
    // which its edges' samples lie between); points beyond a tip, where the curve is no graph
    // over the tangent, lie on the other branch.
    let mut sides = [false; 2];
    for &p in pts {
        let (u, h) = ((p - x).dot(t) / ell, (p - x).dot(n) / ell);
        if curve_conic_height(abc, u).is_some_and(|hc| (hc - h).abs() <= 1e-6 * (1.0 + h.abs())) {
            sides[usize::from(u > 0.0)] = true;
        }
    }
    if sides != [true; 2] {
        return None;
    }
    Some((n, abc))
}

/// The model of a coarse plane-curve vertex as the [`conic_fit`] through it and its four ring
/// points, when some ring point's chord turns from the tangent by more than
/// [`CONIC_SLOPE_DEG`]; `None` (keep the circle-plus-polynomial fit) otherwise.
fn coarse_conic_model(
    x: DVec3,
    m: &VertexModel,
    pts: &[[f64; 3]],
    ell: f64,
    binormal: DVec3,
) -> Option<(VertexModel, HigherModel)> {
    let n0 = DVec3::from(m.normal);
    let t0 = n0.cross(binormal);
    let pts: Vec<DVec3> = pts.iter().map(|&p| DVec3::from(p)).collect();
    let slope = CONIC_SLOPE_DEG.to_radians().tan();
    if !pts
        .iter()
        .any(|&p| (p - x).dot(n0).abs() > slope * (p - x).dot(t0).abs())
    {
        return None;
    }
    let (n, abc) = conic_fit(x, n0, binormal, &pts, ell)?;
    let t = n.cross(binormal);
    // The neighbours: on each side of the vertex, the ring point on the conic's branch
    // nearest along the tangent (`conic_fit` found one on each side).
    let mut span = [f64::NEG_INFINITY, f64::INFINITY];
    for &p in &pts {
        let (u, h) = ((p - x).dot(t) / ell, (p - x).dot(n) / ell);
        if curve_conic_height(abc, u).is_some_and(|hc| (hc - h).abs() <= 1e-6 * (1.0 + h.abs())) {
            let side = usize::from(u > 0.0);
            span[side] = if u > 0.0 {
                span[side].min(u)
            } else {
                span[side].max(u)
            };
        }
    }
    if !(span[0] < 0.0 && span[1] > 0.0 && span[1].is_finite() && span[0].is_finite()) {
        return None;
    }
    let (t, n3): ([f64; 3], [f64; 3]) = (t.into(), n.into());
    let q = 0.5 * abc[0] / ell;
    let h = outer(t, t).map(|r| r.map(|v| q * v));
    Some((
        VertexModel {
            normal: n3,
            h,
            weight: m.weight,
        },
        HigherModel {
            origin: x.into(),
            t: [t, [0.0; 3]],
            scale: ell,
            c: [0.0; 9],
            form: [0.0; 3],
            conic: Some((abc, span)),
        },
    ))
}

/// Whether |h| > hypot(u, w) (the point is no graph over the tangent plane), deciding on the
/// squares where they are clear by far more than their rounding and with `hypot` only near
/// the tie, so the answer is `hypot`'s, at a fraction of its cost.
fn steeper(h: f64, u: f64, w: f64) -> bool {
    let (h2, r2) = (h * h, u * u + w * w);
    // Scaled ring coordinates are of order 1: no overflow or underflow below these bounds.
    if r2 > 1e-200 && r2 < 1e200 && h2 < 1e200 {
        if h2 > r2 * (1.0 + 1e-12) {
            return true;
        }
        if h2 < r2 * (1.0 - 1e-12) {
            return false;
        }
    }
    h.abs() > u.hypot(w)
}

/// The normal equations of the height fit with the monomials `used` over the scaled points
/// `uwh` (tangential u, w and height h), less the conic of curvature form `form`.
fn normal_equations(uwh: &[[f64; 3]], form: [f64; 3], used: &[usize]) -> Normal {
    // The term counts in use, as constants, so that the loops unroll.
    match used.len() {
        3 => normal_equations_k::<3>(uwh, form, used),
        4 => normal_equations_k::<4>(uwh, form, used),
        5 => normal_equations_k::<5>(uwh, form, used),
        9 => normal_equations_k::<9>(uwh, form, used),
        14 => normal_equations_k::<14>(uwh, form, used),
        _ => normal_equations_k::<MAX_TERMS>(uwh, form, used),
    }
}

/// [`normal_equations`] with `K` ≥ `used.len()` terms (the rest zero). Only the upper
/// triangle is summed and then mirrored: the products commute exactly, so the matrix is the
/// one the full double loop gives.
fn normal_equations_k<const K: usize>(uwh: &[[f64; 3]], form: [f64; 3], used: &[usize]) -> Normal {
    let k = used.len().min(K);
    let mut ata = [[0.0; K]; K];
    let mut atb = [0.0; K];
    for &[u, w, h] in uwh {
        let h = h - conic_height(form, u, w).unwrap_or(0.0);
        let all = monomials(u, w);
        let mut mu = [0.0; K];
        for (m, &i) in mu.iter_mut().zip(used) {
            *m = all[i];
        }
        for i in 0..K {
            let mi = mu[i];
            for j in i..K {
                ata[i][j] += mi * mu[j];
            }
            atb[i] += mi * h;
        }
    }
    let mut full = [[0.0; MAX_TERMS]; MAX_TERMS];
    let mut rhs = [0.0; MAX_TERMS];
    for i in 0..k {
        for j in 0..k {
            full[i][j] = if j >= i { ata[i][j] } else { ata[j][i] };
        }
        rhs[i] = atb[i];
    }
    (full, rhs)
}

/// Gaussian elimination with partial pivoting on the leading `n` × `n` block; `None` when
/// nearly singular.
fn solve_n(
    mut a: [[f64; MAX_TERMS]; MAX_TERMS],
    mut b: [f64; MAX_TERMS],
    n: usize,
) -> Option<[f64; MAX_TERMS]> {
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
    let mut x = [0.0; MAX_TERMS];
    for r in (0..n).rev() {
        let mut s = b[r];
        for k in r + 1..n {
            s -= a[r][k] * x[k];
        }
        x[r] = s / a[r][r];
    }
    Some(x)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// At the coarse tip of a 1 × 0.2 ellipse (cells turning by tens of degrees) the conic
    /// model's normal and edge-midpoint targets are exact; the circle-plus-polynomial fit of
    /// the same ring fails.
    #[test]
    fn coarse_conic_model_is_exact_on_an_ellipse() {
        let e = |t: f64| DVec3::new(t.cos(), 0.2 * t.sin(), 0.0);
        let on = |p: DVec3| (p.x * p.x + p.y * p.y / 0.04).sqrt() - 1.0;
        let ts = [-0.75, -0.35, 0.35, 0.75];
        let pts: Vec<[f64; 3]> = ts.iter().map(|&t| e(t).into()).collect();
        let m = VertexModel {
            normal: unit(DVec3::new(1.0, 0.05, 0.0)).into(),
            h: [[0.0; 3]; 3],
            weight: 1.0,
        };
        let ell = 0.5 * (e(0.35) - e(-0.35)).length();
        let (cm, hm) = refine_model(2, e(0.0).into(), &m, &pts, ell, Height::CENTRED).unwrap();
        assert!(hm.conic.is_some());
        assert!(
            (DVec3::from(cm.normal) - DVec3::X).length() < 1e-9,
            "{:?}",
            cm.normal
        );
        let chord = on(0.5 * (e(0.0) + e(0.35))).abs();
        for t in [0.35, -0.35] {
            let xs = [e(0.0).into(), e(t).into()];
            let p = 0.5 * (e(0.0) + e(t));
            let d = DVec3::from(cm.correction(p.into(), &xs, 0.5))
                + hm.correction(p.into(), &xs, 0.5) * DVec3::from(cm.normal);
            assert!(
                on(p + d).abs() < 1e-9 * chord,
                "{t}: {} vs {chord}",
                on(p + d)
            );
        }
        // Over the same ring the circle plus cubic and quartic terms has no fit: the ring
        // points beyond the tip's neighbours are no graph over its tangent.
        let used = [0, 2, 5, 9];
        assert!(refine_with(2, e(0.0).into(), &m, &pts, ell, &used, Height::CENTRED).is_none());
    }

    /// Next to the 41° tip of a 1 × 0.2 ellipse, points offset from the curve along its
    /// normals (a boundary layer's outer cells, which inherit the model) reach tangent
    /// coordinates near the end of the conic's branch. The conic term of an edge's correction
    /// between the tip's column and the vertex's then grows smoothly with the offset, with the
    /// wall's sign and within 4× the wall's up to 0.9 of the tip's radius of curvature (0.04),
    /// instead of following the branch towards its vertical tangent (7.8× at 0.028) and
    /// jumping where a corner leaves it.
    #[test]
    fn coarse_conic_goes_on_along_its_tangent_beyond_its_neighbours() {
        let b = 0.2;
        let at = |t: f64, d: f64| {
            let n = unit(DVec3::new(b * t.cos(), t.sin(), 0.0));
            DVec3::new(t.cos(), b * t.sin(), 0.0) + d * n
        };
        let ts = [-0.1512, 0.0, 0.1512, 0.266, 0.3569];
        let pts: Vec<[f64; 3]> = [0, 1, 3, 4].map(|i| at(ts[i], 0.0).into()).to_vec();
        let m = VertexModel {
            normal: unit(DVec3::new(b * ts[2].cos(), ts[2].sin(), 0.0)).into(),
            h: [[0.0; 3]; 3],
            weight: 1.0,
        };
        let ell = 0.5 * (at(ts[3], 0.0) - at(ts[1], 0.0)).length();
        let (_, hm) =
            refine_model(2, at(ts[2], 0.0).into(), &m, &pts, ell, Height::CENTRED).unwrap();
        assert!(hm.conic.is_some());
        let conic_term = |d: f64| {
            let (x, y) = (at(ts[2], d), at(ts[1], d));
            hm.correction((0.5 * (x + y)).into(), &[x.into(), y.into()], 0.5)
        };
        let wall = conic_term(0.0);
        assert!(wall.abs() > 1e-4, "{wall:e}");
        for k in 1..=36 {
            let d = 1e-3 * k as f64;
            let c = conic_term(d);
            assert!(
                c * wall > 0.0 && c.abs() <= 4.0 * wall.abs(),
                "offset {d}: {c:e} against the wall's {wall:e}"
            );
        }
    }
}
