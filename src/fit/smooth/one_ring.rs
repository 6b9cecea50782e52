//! One-ring boundary models (see the parent module's docs): the 2D parabola through a vertex's
//! two boundary neighbours ([`fit_parabola`]) and the 3D least-squares quadric over the
//! vertices of the boundary faces around it ([`fan_model`]), with the small dense solves and
//! tensor helpers they share with the two-ring refit.
//!
//! Input: a vertex and its neighbours' coordinates. Output: a unit normal and the curvature
//! tensor H (H · normal = 0), or `None` for a degenerate or non-graph fan.

use super::VertexModel;
use crate::math::linalg::{DVec3, unit};
use crate::mesh::{LinearMesh, Topology};

/// The 3D model at vertex `v` from the boundary faces `faces` around it, with the fan's length
/// scale ℓ and its unit area-weighted normal; `None` when the fan is degenerate, has fewer than
/// 5 neighbour vertices, or a face normal is more than acos(`cos_max`) from the fan normal (the
/// model is `None` when the quadric fit fails).
pub(in crate::fit) fn fan_model(
    mesh: &LinearMesh,
    topo: &Topology,
    v: u32,
    faces: &[u32],
    cos_max: f64,
) -> Option<(Option<VertexModel>, f64, [f64; 3])> {
    let x = |w: u32| DVec3::from(mesh.coords[w as usize]);
    let quads: Vec<[DVec3; 4]> = faces
        .iter()
        .map(|&f| topo.faces[f as usize].map(x))
        .collect();
    let mut nb: Vec<u32> = faces
        .iter()
        .flat_map(|&f| topo.faces[f as usize])
        .filter(|&w| w != v)
        .collect();
    nb.sort_unstable();
    nb.dedup();
    let nb: Vec<DVec3> = nb.into_iter().map(x).collect();
    quad_fan_model(x(v), &quads, &nb, cos_max)
}

/// [`fan_model`] at the point `xv` from its fan's quads (corners in the facets' order) and
/// its distinct neighbour points `nb`: a wall's fan at a periodic seam is completed by the
/// other side's quads carried over by the periodic transform.
pub(in crate::fit) fn quad_fan_model(
    xv: DVec3,
    quads: &[[DVec3; 4]],
    nb: &[DVec3],
    cos_max: f64,
) -> Option<(Option<VertexModel>, f64, [f64; 3])> {
    let mut area = DVec3::ZERO;
    let mut normals = Vec::with_capacity(quads.len());
    let mut total_area = 0.0;
    for q in quads {
        let a = (q[2] - q[0]).cross(q[3] - q[1]);
        area += a;
        let l = a.length();
        total_area += 0.5 * l;
        normals.push(a / l.max(f64::MIN_POSITIVE));
    }
    let la = area.length();
    if la == 0.0 || nb.len() < 5 {
        return None;
    }
    let n0 = area / la;
    if normals.iter().any(|nf| nf.dot(n0) < cos_max) {
        return None;
    }
    let ell = (total_area / quads.len() as f64).sqrt();
    let pts: Vec<[f64; 3]> = nb.iter().map(|&w| (w - xv).into()).collect();
    let model = fit_quadric(n0.into(), &pts, ell).map(|(normal, h)| VertexModel {
        normal,
        h,
        weight: 1.0,
    });
    Some((model, ell, n0.into()))
}

/// 2D model at x through its boundary neighbours a and b: (normal, H).
pub(in crate::fit) fn fit_parabola(
    x: [f64; 3],
    a: [f64; 3],
    b: [f64; 3],
) -> Option<([f64; 3], [[f64; 3]; 3])> {
    let x = DVec3::from(x);
    let (ua, ub) = (DVec3::from(a) - x, DVec3::from(b) - x);
    let mut t = unit(ub - ua);
    let mut fitted = None;
    for _ in 0..3 {
        let n = DVec3::new(-t.y, t.x, 0.0);
        let (xa, ya, xb, yb) = (ua.dot(t), ua.dot(n), ub.dot(t), ub.dot(n));
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
        t = unit(t + c1 * n);
    }
    let (t, c2) = fitted?;
    let t: [f64; 3] = t.into();
    let n = [-t[1], t[0], 0.0];
    let h = outer(t, t).map(|r| r.map(|c| c2 * c));
    Some((n, h))
}

/// 3D model: least-squares quadric height over the tangent plane of normal n0 through the
/// neighbour offsets `pts` (relative to the vertex); `scale` ~ the edge length.
pub(super) fn fit_quadric(
    n0: [f64; 3],
    pts: &[[f64; 3]],
    scale: f64,
) -> Option<([f64; 3], [[f64; 3]; 3])> {
    let mut n = DVec3::from(n0);
    let mut q = [0.0; 3];
    let mut frame = tangent_frame(n.into());
    for _ in 0..3 {
        frame = tangent_frame(n.into());
        let (t1, t2) = (DVec3::from(frame.0), DVec3::from(frame.1));
        // Unknowns (a, b, c, d, e) of η = aξ² + bξζ + cζ² + dξ + eζ in scaled coordinates.
        let mut ata = [[0.0; 5]; 5];
        let mut atb = [0.0; 5];
        for p in pts {
            let p = DVec3::from(*p);
            let (u, v, h) = (p.dot(t1) / scale, p.dot(t2) / scale, p.dot(n) / scale);
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
        n = unit(n - (d * t1 + e * t2));
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
    Some((DVec3::from(t1).cross(DVec3::from(t2)).into(), h))
}

pub(super) fn tangent_frame(n: [f64; 3]) -> ([f64; 3], [f64; 3]) {
    let n = DVec3::from(n);
    let a = if n.x.abs() < 0.6 { DVec3::X } else { DVec3::Y };
    let t1 = unit(n.cross(a));
    (t1.into(), n.cross(t1).into())
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

pub(super) fn outer(a: [f64; 3], b: [f64; 3]) -> [[f64; 3]; 3] {
    a.map(|ai| b.map(|bj| ai * bj))
}
pub(super) fn sym_outer(a: [f64; 3], b: [f64; 3]) -> [[f64; 3]; 3] {
    let (m, n) = (outer(a, b), outer(b, a));
    std::array::from_fn(|i| std::array::from_fn(|j| m[i][j] + n[i][j]))
}
