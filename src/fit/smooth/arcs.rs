//! Boundary targets on coarse smooth surfaces from the vertex normals alone (see the parent
//! module's docs): circular arcs along the boundary edges and across the boundary faces.
//!
//! Where neighbouring vertex normals turn by more than [`COARSE_TURN_DEG`] (a torus tube of
//! eight cells, 45° per cell), the height functions of [`super::higher`] and the one-ring
//! quadric are fitted to points a quarter-turn or more away, far outside the range where a
//! polynomial follows the surface (edge-midpoint errors near 40 % of the chord's sagitta
//! have been measured), while the vertex normals stay accurate (they are set by the nearest
//! facets). There the boundary samples take their targets from the normals:
//! * **edge midpoint** of a, b with normals n_a, n_b: the chord d = b − a projected onto each
//!   tangent plane gives unit tangents t_a, t_b turning by φ; the target is the chord midpoint
//!   moved by (|d| / 2) tan(φ / 4) along t_a − t_b, the midpoint of the circular arc with
//!   those end tangents, so exact on any circle through a and b whose plane holds the normals
//!   (a torus's tube and equators, a sphere's great circles) and of order |d|⁴ elsewhere;
//! * **face centre**: the arcs across the face between the targets of opposite edge
//!   midpoints (their normals the normalised sums of the end normals), averaged over the two
//!   directions.
//!
//! Along a grid line whose five points around a coarse vertex fix a conic ([`LineConic`], exact
//! on ellipses), an edge midpoint takes that conic's point instead of the circle's: next to an
//! ellipse's coarse tip (an O-grid's leading and trailing edges, four cells around the tip) the
//! circular arc on the exact normals is off by 17 % of the chord's sagitta, the conic not at all.
//! Only where the conic's plane holds the surface normal ([`LineConic::is_normal_section`]).
//!
//! Input: the corners and normals of one boundary entity. Output: the displacement of its
//! sample from the multilinear point, or `None` (degenerate chord or normals) to keep the
//! models' target. Normals may point either way: only the lines they span matter.

use crate::math::linalg::{DVec3, unit};

/// A smooth boundary vertex is coarse when the normal of a vertex it shares a boundary facet
/// with turns from its own by more than this angle (degrees).
pub(super) const COARSE_TURN_DEG: f64 = 30.0;

/// A grid line's conic ([`LineConic`]) replaces the circular arcs only where its normal at the
/// vertex is within this angle (degrees) of the surface normal.
const LINE_CONIC_NORMAL_DEG: f64 = 5.0;

/// Displacement of the edge midpoint (a + b) / 2 onto the circular arc from a to b whose
/// tangents at a and b are the chord's projections onto the planes normal to `na` and `nb`.
pub(super) fn edge_arc(a: DVec3, b: DVec3, na: DVec3, nb: DVec3) -> Option<DVec3> {
    let d = b - a;
    let l = d.length();
    let (ta, tb) = (d - d.dot(na) * na, d - d.dot(nb) * nb);
    let (la, lb) = (ta.length(), tb.length());
    if !(l > 0.0 && la > 1e-6 * l && lb > 1e-6 * l) {
        return None;
    }
    let (ta, tb) = (ta / la, tb / lb);
    let s = ta - tb;
    let ls = s.length();
    if ls <= 1e-12 {
        // Parallel tangents: the chord is the arc.
        return Some(DVec3::ZERO);
    }
    let phi = ta.dot(tb).clamp(-1.0, 1.0).acos();
    Some(0.5 * l * (0.25 * phi).tan() * (s / ls))
}

/// The tangent at `v` of the circle through `a`, `v` and `b` (unnormalised; `None` for
/// coincident points): the chord directions weighted by the opposite chord's length.
fn circle_tangent(a: DVec3, v: DVec3, b: DVec3) -> Option<DVec3> {
    let (da, db) = (v - a, b - v);
    let (la, lb) = (da.length(), db.length());
    (la > 0.0 && lb > 0.0).then(|| lb / la * da + la / lb * db)
}

/// The conic through a vertex and four points of one of its grid lines, in the vertex's frame:
/// A u² + B uη + C η² − 2η = 0 with u, η the coordinates along the conic's tangent `t` and
/// normal `n` at the vertex, in units of `ell` ([`super::higher::conic_fit`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) struct LineConic {
    t: DVec3,
    n: DVec3,
    abc: [f64; 3],
    ell: f64,
}

impl LineConic {
    /// Values per conic in a per-vertex record ([`LineConic::write`], [`LineConic::read`]).
    pub(super) const LEN: usize = 10;

    /// Writes the conic into `out` ([`LineConic::LEN`] values).
    pub(super) fn write(&self, out: &mut [f64]) {
        out[0..3].copy_from_slice(&self.t.to_array());
        out[3..6].copy_from_slice(&self.n.to_array());
        out[6..9].copy_from_slice(&self.abc);
        out[9] = self.ell;
    }

    /// The conic written by [`LineConic::write`]; `None` for an unset slot (all zero).
    pub(super) fn read(r: &[f64]) -> Option<LineConic> {
        (r[9] > 0.0).then(|| LineConic {
            t: DVec3::new(r[0], r[1], r[2]),
            n: DVec3::new(r[3], r[4], r[5]),
            abc: [r[6], r[7], r[8]],
            ell: r[9],
        })
    }

    /// The conic of the grid line of `v` through `a` and `b` and the next points `[a2, b2]`
    /// beyond them; `None` where the five are (nearly) collinear or fix no conic whose branch
    /// through `v` holds `a` and `b`.
    pub(super) fn fit(a: DVec3, v: DVec3, b: DVec3, [a2, b2]: [DVec3; 2]) -> Option<LineConic> {
        let plane = (a - v).cross(b - v);
        let lp = plane.length();
        let d = b - a;
        if !(lp > 1e-9 * d.length_squared()) {
            return None;
        }
        let binormal = plane / lp;
        let n0 = unit(binormal.cross(d));
        let ell = 0.5 * d.length();
        let (n, abc) = super::higher::conic_fit(v, n0, binormal, &[a, b, a2, b2], ell)?;
        Some(LineConic {
            t: n.cross(binormal),
            n,
            abc,
            ell,
        })
    }

    /// Whether the conic's plane holds the surface normal `normal` at its vertex to within
    /// [`LINE_CONIC_NORMAL_DEG`] (a normal section, whose curvature is the surface's): only
    /// then does it replace the circular arcs. A grid line that leaves the normal plane also
    /// turns within the tangent plane, and its conic's midpoints move sideways by that share,
    /// which the face centres' arcs across the other grid direction do not: the parallels of
    /// a coarse torus (16 around, 8 around the tube) off its equators, which at the tube's
    /// top and bottom turn within the tangent plane alone, left the faces' centres between
    /// their edges' midpoints and held back 160 of its 192 elements at half their targets.
    pub(super) fn is_normal_section(&self, normal: DVec3) -> bool {
        let len = normal.length();
        len > 0.0 && self.n.dot(normal).abs() >= LINE_CONIC_NORMAL_DEG.to_radians().cos() * len
    }

    /// Displacement of the midpoint of the chord from this conic's vertex `v` to its grid-line
    /// neighbour `b` onto the conic, along the chord's normal in the conic's plane (so the
    /// circle's arc midpoint on a circle). `None` when `b` is not on this conic (the vertex's
    /// other grid line) or the chord's normal meets it only far off.
    pub(super) fn edge_midpoint(&self, v: DVec3, b: DVec3) -> Option<DVec3> {
        let [qa, qb, qc] = self.abc;
        let f = |u: f64, h: f64| qa * u * u + qb * u * h + qc * h * h - 2.0 * h;
        let e = b - v;
        let (ub, hb) = (e.dot(self.t) / self.ell, e.dot(self.n) / self.ell);
        let len = ub.hypot(hb);
        // On this line's plane, and on the conic: b is one of the points it was fitted through.
        let binormal = self.t.cross(self.n);
        let grad = (2.0 * qa * ub + qb * hb).hypot(qb * ub + 2.0 * qc * hb - 2.0);
        if !(len > 0.0
            && e.dot(binormal).abs() <= 1e-6 * e.length()
            && f(ub, hb).abs() <= 1e-6 * grad * len)
        {
            return None;
        }
        let (mu, mh) = (0.5 * ub, 0.5 * hb);
        let (cu, ch) = (-hb / len, ub / len);
        // f(m + s c) = α s² + β s + γ.
        let alpha = qa * cu * cu + qb * cu * ch + qc * ch * ch;
        let beta = 2.0 * qa * mu * cu + qb * (mu * ch + mh * cu) + 2.0 * qc * mh * ch - 2.0 * ch;
        let gamma = f(mu, mh);
        let s = if alpha.abs() <= 1e-12 * beta.abs() {
            -gamma / beta
        } else {
            let disc = beta * beta - 4.0 * alpha * gamma;
            if !(disc >= 0.0) {
                return None;
            }
            // The root nearer the chord (the other lies on the conic's far side).
            let q = -0.5 * (beta + beta.signum() * disc.sqrt());
            let (s1, s2) = (q / alpha, gamma / q);
            if s1.abs() < s2.abs() { s1 } else { s2 }
        };
        (s.is_finite() && s.abs() <= 0.5 * len).then(|| s * self.ell * (cu * self.t + ch * self.n))
    }
}

/// The tangent at `v` of its grid line through `a` and `b`: with the next points `outer` beyond
/// them, that of the conic through the five ([`LineConic`], exact on ellipses: next to an
/// ellipse's coarse tip the circle's is off by degrees), else (or when that fails) that of the
/// circle through the three.
fn line_tangent(a: DVec3, v: DVec3, b: DVec3, outer: Option<[DVec3; 2]>) -> Option<DVec3> {
    let circle = circle_tangent(a, v, b)?;
    let conic = outer
        .and_then(|o| LineConic::fit(a, v, b, o))
        .map(|c| c.t.dot(circle).signum() * c.t);
    Some(conic.unwrap_or(circle / circle.length()))
}

/// The normal at a regular vertex `v` (four boundary quads) from its two grid lines: the
/// cross product of the tangents of the curves through each opposite pair of its edge
/// neighbours (and, where given in `outer`, the next points beyond them; [`line_tangent`]),
/// oriented along the unit normal `n_ref`. Exact wherever the grid lines are circles (a
/// torus's or any surface of revolution's meridians and parallels, a sphere's great or small
/// circles) or, with the outer points, ellipses, where the fan's and the quadric's normals are
/// not (on an eight-cell torus tube they are off by up to 4°). `None` when the two tangents
/// are (nearly) parallel or the normal turns from `n_ref` by more than 45°.
pub(super) fn grid_normal(
    v: DVec3,
    pairs: [(DVec3, DVec3); 2],
    outer: [Option<[DVec3; 2]>; 2],
    n_ref: DVec3,
) -> Option<DVec3> {
    let t1 = line_tangent(pairs[0].0, v, pairs[0].1, outer[0])?;
    let t2 = line_tangent(pairs[1].0, v, pairs[1].1, outer[1])?;
    let c = t1.cross(t2);
    let l = c.length();
    if !(l > 0.1) {
        return None;
    }
    let n = c / l;
    let cos = n.dot(n_ref);
    (cos.abs() > std::f64::consts::FRAC_1_SQRT_2).then(|| cos.signum() * n)
}

/// The normal halfway between `na` and `nb` (either orientation of `nb`).
fn mid_normal(na: DVec3, nb: DVec3) -> Option<DVec3> {
    let s = na + na.dot(nb).signum() * nb;
    (s.length() > 1e-12).then(|| unit(s))
}

/// Displacement of the centre of the boundary quad with corners `x` and normals `n` (lattice
/// order: corner i at (i mod 2, i / 2) of the face's parameters) from the corners' average;
/// `edge(i, j)` is the displacement of the midpoint of its edge from corner i to corner j
/// ([`edge_arc`], or a grid line's conic).
pub(super) fn face_arc(
    x: &[DVec3; 4],
    n: &[DVec3; 4],
    edge: impl Fn(usize, usize) -> Option<DVec3>,
) -> Option<DVec3> {
    let centre = 0.25 * (x[0] + x[1] + x[2] + x[3]);
    let mut sum = DVec3::ZERO;
    // Across from the midpoint of edge (i, j) to that of the opposite edge (k, l).
    for [i, j, k, l] in [[0, 1, 2, 3], [0, 2, 1, 3]] {
        let m1 = 0.5 * (x[i] + x[j]) + edge(i, j)?;
        let m2 = 0.5 * (x[k] + x[l]) + edge(k, l)?;
        let (n1, n2) = (mid_normal(n[i], n[j])?, mid_normal(n[k], n[l])?);
        sum += 0.5 * (m1 + m2) + edge_arc(m1, m2, n1, n2)?;
    }
    Some(0.5 * sum - centre)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn torus(psi: f64, th: f64) -> (DVec3, DVec3) {
        let (r0, r) = (1.0, 0.5);
        let n = DVec3::new(th.cos() * psi.cos(), th.cos() * psi.sin(), th.sin());
        let x = DVec3::new(
            (r0 + r * th.cos()) * psi.cos(),
            (r0 + r * th.cos()) * psi.sin(),
            r * th.sin(),
        );
        (x, n)
    }

    fn torus_distance(x: DVec3) -> f64 {
        ((x.x.hypot(x.y) - 1.0).hypot(x.z) - 0.5).abs()
    }

    /// On a coarse torus (16 × 8 facets) every grid line's conic puts its edge midpoints on
    /// the torus, but only the meridians' are normal sections at every vertex; the parallels'
    /// only on the equators: elsewhere they turn within the tangent plane too (alone at the
    /// tube's top and bottom), sideways to the faces' arcs across them.
    #[test]
    fn only_normal_sections_of_a_coarse_torus_keep_their_line_conics() {
        let (dpsi, dth) = (std::f64::consts::TAU / 16.0, std::f64::consts::TAU / 8.0);
        for j in 0..8 {
            let th = j as f64 * dth;
            let (v, n) = torus(0.0, th);
            let meridian = |k: f64| torus(0.0, th + k * dth).0;
            let parallel = |k: f64| torus(k * dpsi, th).0;
            for (line, normal_section) in [
                (&meridian as &dyn Fn(f64) -> DVec3, true),
                (&parallel, j % 4 == 0),
            ] {
                let c = LineConic::fit(line(-1.0), v, line(1.0), [line(-2.0), line(2.0)]).unwrap();
                assert_eq!(c.is_normal_section(n), normal_section, "{j}");
                assert_eq!(c.is_normal_section(-n), normal_section, "{j}");
                let m = 0.5 * (v + line(1.0)) + c.edge_midpoint(v, line(1.0)).unwrap();
                let off = torus_distance(m);
                assert!(off < 1e-9, "{j}: {off:e}");
            }
        }
    }

    /// On a circle (normals in its plane, either orientation) the edge target is exact
    /// at any resolution; the chord midpoint is not.
    #[test]
    fn edge_arc_is_exact_on_circles() {
        let c = |t: f64| DVec3::new(2.0 * t.cos(), 0.3, 2.0 * t.sin());
        let nrm = |t: f64| DVec3::new(t.cos(), 0.0, t.sin());
        for (t0, t1) in [(0.1, 0.9), (0.0, 1.6), (-0.2, 0.05)] {
            let (a, b) = (c(t0), c(t1));
            let m = 0.5 * (a + b) + edge_arc(a, b, nrm(t0), -nrm(t1)).unwrap();
            let r = (m - DVec3::new(0.0, 0.3, 0.0)).length();
            assert!((r - 2.0).abs() < 1e-12, "{t0} {t1}: {r}");
        }
    }

    /// On a coarse torus the grid lines' circles give the exact normal at every vertex
    /// (pointing along the reference, whichever way that is); the average of the four quads'
    /// normals turns from it by degrees off the equators.
    #[test]
    fn grid_normal_is_exact_on_a_coarse_torus() {
        let (dpsi, dth) = (std::f64::consts::TAU / 16.0, std::f64::consts::TAU / 8.0);
        let mut fan_worst = 0.0f64;
        for j in 0..8 {
            let th = j as f64 * dth;
            let (v, n) = torus(0.3, th);
            let p = |a: f64, b: f64| torus(0.3 + a * dpsi, th + b * dth).0;
            let pairs = [(p(-1.0, 0.0), p(1.0, 0.0)), (p(0.0, -1.0), p(0.0, 1.0))];
            for sign in [1.0, -1.0] {
                let g = grid_normal(v, pairs, [None; 2], sign * unit(n + 0.3 * DVec3::Z)).unwrap();
                assert!((g - sign * n).length() < 1e-12, "{th}: {g:?} vs {n:?}");
            }
            let quad = |a: f64, b: f64| {
                let c = [p(0.0, 0.0), p(a, 0.0), p(a, b), p(0.0, b)];
                (c[2] - c[0]).cross(c[3] - c[1]) * (a * b)
            };
            let fan = unit(quad(1.0, 1.0) + quad(-1.0, 1.0) + quad(1.0, -1.0) + quad(-1.0, -1.0));
            fan_worst = fan_worst.max(fan.dot(n).abs().clamp(-1.0, 1.0).acos().to_degrees());
        }
        assert!(fan_worst > 1.0, "{fan_worst}");
    }

    /// Along an ellipse's coarse tip the tangent of the conic through five grid points is
    /// exact; the circle through three is off by degrees next to the tip.
    #[test]
    fn line_tangent_is_exact_on_a_coarse_ellipse() {
        let e = |t: f64| DVec3::new(t.cos(), 0.2 * t.sin(), 0.7);
        let ts = [-0.35, 0.0, 0.35, 0.75, 1.2];
        let exact = unit(DVec3::new(-(0.35f64).sin(), 0.2 * (0.35f64).cos(), 0.0));
        let (a, v, b) = (e(ts[1]), e(ts[2]), e(ts[3]));
        let conic = line_tangent(a, v, b, Some([e(ts[0]), e(ts[4])])).unwrap();
        assert!((conic - exact).length() < 1e-9, "{conic:?} vs {exact:?}");
        let circle = unit(line_tangent(a, v, b, None).unwrap());
        assert!(circle.dot(exact).acos().to_degrees() > 1.0, "{circle:?}");
    }

    /// On the eight-by-sixteen torus (45° around the tube per cell) with exact normals, the
    /// edge and face targets are within 2 % and 3 % of the chord's largest distance from the
    /// torus.
    #[test]
    fn arcs_follow_a_coarse_torus() {
        let (dpsi, dth) = (std::f64::consts::TAU / 16.0, std::f64::consts::TAU / 8.0);
        let (mut worst_chord, mut worst_edge, mut worst_face) = (0.0f64, 0.0f64, 0.0f64);
        for i in 0..16 {
            for j in 0..8 {
                let (ps, th) = (i as f64 * dpsi, j as f64 * dth);
                let c = [
                    torus(ps, th),
                    torus(ps + dpsi, th),
                    torus(ps, th + dth),
                    torus(ps + dpsi, th + dth),
                ];
                let (x, n) = (c.map(|p| p.0), c.map(|p| p.1));
                for (a, b) in [(0, 1), (0, 2)] {
                    let m = 0.5 * (x[a] + x[b]);
                    worst_chord = worst_chord.max(torus_distance(m));
                    let e = m + edge_arc(x[a], x[b], n[a], n[b]).unwrap();
                    worst_edge = worst_edge.max(torus_distance(e));
                }
                let arc = |i: usize, j: usize| edge_arc(x[i], x[j], n[i], n[j]);
                let f = 0.25 * (x[0] + x[1] + x[2] + x[3]) + face_arc(&x, &n, arc).unwrap();
                worst_face = worst_face.max(torus_distance(f));
            }
        }
        assert!(
            worst_edge < 0.02 * worst_chord,
            "{worst_edge} vs {worst_chord}"
        );
        assert!(
            worst_face < 0.03 * worst_chord,
            "{worst_face} vs {worst_chord}"
        );
    }
}
