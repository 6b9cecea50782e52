//! The analytic walls: ellipse, circle and the NACA 00xx airfoil with a closed trailing edge.
//!
//! Input: a [`Wall`] and a parameter, a count of points, or a query point. Output: points of
//! the wall and its unit outward normals, the wall's chord and centre, the closest wall point and
//! the distance to the wall. Invariant: every point returned lies on the analytic curve up to
//! rounding; around the airfoil the points are cosine-spaced in arc length on each surface.

use super::{GenerateError, bad};
use std::f64::consts::PI;

/// The analytic wall curve.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Wall {
    /// Ellipse with semi-axes 1 (along x) and `thickness` (along y), centred at the origin.
    Ellipse { thickness: f64 },
    /// Circle of radius 1 about the origin.
    Circle,
    /// Symmetric NACA 00xx airfoil of chord 1 (x from 0 to 1), maximum thickness `thickness`
    /// (0.12 for NACA 0012), closed trailing edge.
    Naca { thickness: f64 },
}

impl Wall {
    /// The ellipse of the `ogrid` default: minor/major semi-axis ratio 0.2.
    pub const ELLIPSE: Wall = Wall::Ellipse { thickness: 0.2 };
    /// NACA 0012, the `cgrid` default.
    pub const NACA_0012: Wall = Wall::Naca { thickness: 0.12 };

    /// This wall with its thickness replaced where given (the circle has none).
    pub fn with_thickness(self, thickness: Option<f64>) -> Wall {
        match (self, thickness) {
            (Wall::Ellipse { .. }, Some(thickness)) => Wall::Ellipse { thickness },
            (Wall::Naca { .. }, Some(thickness)) => Wall::Naca { thickness },
            (wall, _) => wall,
        }
    }
}

/// NACA 4-digit half thickness in the parameter u = √x, and its u-derivative.
pub(super) fn naca_half(t: f64, u: f64) -> (f64, f64) {
    let (u2, u3) = (u * u, u * u * u);
    let (u4, u5) = (u2 * u2, u2 * u3);
    let y = 5.0 * t * (0.2969 * u - 0.126 * u2 - 0.3516 * u4 + 0.2843 * u4 * u2 - 0.1036 * u4 * u4);
    let dy = 5.0 * t * (0.2969 - 0.252 * u - 1.4064 * u3 + 1.7058 * u5 - 0.8288 * u5 * u2);
    (y, dy)
}

/// Arc length of the airfoil's upper surface from the leading edge to parameter u = √x
/// (5-point Gauss–Legendre on 64 panels; the integrand √(4u² + y'(u)²) is smooth in u).
pub(super) fn naca_arc(t: f64, u: f64) -> f64 {
    pub(super) const X: [f64; 5] = [
        -0.906_179_845_938_664,
        -0.538_469_310_105_683,
        0.0,
        0.538_469_310_105_683,
        0.906_179_845_938_664,
    ];
    pub(super) const W: [f64; 5] = [
        0.236_926_885_056_189,
        0.478_628_670_499_366,
        0.568_888_888_888_889,
        0.478_628_670_499_366,
        0.236_926_885_056_189,
    ];
    let panels = 64;
    let h = u / panels as f64;
    let mut s = 0.0;
    for p in 0..panels {
        let mid = (p as f64 + 0.5) * h;
        for (x, w) in X.iter().zip(W) {
            let v = mid + 0.5 * h * x;
            let dy = naca_half(t, v).1;
            s += 0.5 * h * w * (4.0 * v * v + dy * dy).sqrt();
        }
    }
    s
}

/// The u = √x at which the upper surface's arc length from the leading edge is `s`.
pub(super) fn naca_u_at_arc(t: f64, s: f64) -> f64 {
    let (mut lo, mut hi) = (0.0, 1.0);
    for _ in 0..60 {
        let mid = 0.5 * (lo + hi);
        if naca_arc(t, mid) < s {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    0.5 * (lo + hi)
}

pub(super) fn normalised(v: [f64; 2]) -> [f64; 2] {
    let l = v[0].hypot(v[1]);
    [v[0] / l, v[1] / l]
}

/// A wall vertex and the unit direction of the grid line leaving it.
#[derive(Clone, Copy, Debug)]
pub(super) struct WallPoint {
    pub(super) p: [f64; 2],
    pub(super) n: [f64; 2],
}

impl Wall {
    /// The chord: 2 for the ellipse and the circle (their major diameter), 1 for the airfoil.
    pub fn chord(&self) -> f64 {
        match self {
            Wall::Ellipse { .. } | Wall::Circle => 2.0,
            Wall::Naca { .. } => 1.0,
        }
    }

    /// The centre of the O-grid's far-field circle: the origin, or mid-chord (0.5, 0).
    pub fn centre(&self) -> [f64; 2] {
        match self {
            Wall::Ellipse { .. } | Wall::Circle => [0.0, 0.0],
            Wall::Naca { .. } => [0.5, 0.0],
        }
    }

    /// The wall as a closed parametric curve, counter-clockwise, periodic in `t` with period
    /// 1, starting at (1, 0) (the airfoil's trailing edge). Ellipse: (cos 2πt, b sin 2πt).
    /// Airfoil: the upper surface for t ∈ [0, ½] with u = √x = 1 − 2t, the lower one for
    /// t ∈ [½, 1] with u = 2t − 1.
    pub fn point(&self, t: f64) -> [f64; 2] {
        let t = t.rem_euclid(1.0);
        match *self {
            Wall::Ellipse { thickness } => {
                let a = 2.0 * PI * t;
                [a.cos(), thickness * a.sin()]
            }
            Wall::Circle => {
                let a = 2.0 * PI * t;
                [a.cos(), a.sin()]
            }
            Wall::Naca { thickness } => {
                if t <= 0.5 {
                    let u = 1.0 - 2.0 * t;
                    [u * u, naca_half(thickness, u).0]
                } else {
                    let u = 2.0 * t - 1.0;
                    [u * u, -naca_half(thickness, u).0]
                }
            }
        }
    }

    /// The wall point closest to `q` and its distance. Exact to rounding: the nearest of 4096
    /// samples of [`Wall::point`] is refined by golden-section search between its neighbours.
    pub fn closest_point(&self, q: [f64; 2]) -> ([f64; 2], f64) {
        let d2 = |t: f64| {
            let p = self.point(t);
            (p[0] - q[0]).powi(2) + (p[1] - q[1]).powi(2)
        };
        let samples = 4096;
        let step = 1.0 / samples as f64;
        let best = (0..samples)
            .map(|k| (d2(k as f64 * step), k))
            .fold((f64::INFINITY, 0), |a, b| if b.0 < a.0 { b } else { a })
            .1;
        // The airfoil parameter has a corner at t = 0 (trailing edge): search each side of it
        // separately so the bracket holds a smooth piece.
        let centre = best as f64 * step;
        let mut result = (f64::INFINITY, centre);
        for (lo, hi) in [(centre - step, centre), (centre, centre + step)] {
            let t = golden(lo, hi, &d2);
            let v = d2(t);
            if v < result.0 {
                result = (v, t);
            }
        }
        (self.point(result.1), result.0.sqrt())
    }

    /// Distance from `q` to the wall ([`Wall::closest_point`]).
    pub fn distance(&self, q: [f64; 2]) -> f64 {
        self.closest_point(q).1
    }

    /// Check the wall's own parameter.
    pub(super) fn check(&self) -> Result<(), GenerateError> {
        match *self {
            Wall::Ellipse { thickness } if !(thickness > 0.0 && thickness <= 1.0) => Err(bad(
                "thickness",
                thickness,
                "an ellipse's minor/major semi-axis ratio must be in (0, 1]",
            )),
            Wall::Naca { thickness } if !(thickness > 0.0 && thickness <= 0.4) => Err(bad(
                "thickness",
                thickness,
                "a NACA 00xx thickness must be in (0, 0.4] (0.12 for NACA 0012)",
            )),
            _ => Ok(()),
        }
    }

    /// `n` wall vertices counter-clockwise from (1, 0), with outward unit normals (the
    /// bisector of the two surface normals at the airfoil's trailing edge).
    pub(super) fn vertices(&self, n: usize) -> Vec<WallPoint> {
        match *self {
            Wall::Ellipse { .. } | Wall::Circle => {
                let b = match *self {
                    Wall::Ellipse { thickness } => thickness,
                    _ => 1.0,
                };
                (0..n)
                    .map(|i| {
                        let a = 2.0 * PI * (i as f64 / n as f64);
                        WallPoint {
                            p: [a.cos(), b * a.sin()],
                            n: normalised([b * a.cos(), a.sin()]),
                        }
                    })
                    .collect()
            }
            Wall::Naca { thickness } => {
                let half = n / 2;
                let total = naca_arc(thickness, 1.0);
                let upper_normal = |u: f64| {
                    let dy = naca_half(thickness, u).1;
                    normalised([-dy, 2.0 * u])
                };
                let mut out = Vec::with_capacity(n);
                for i in 0..n {
                    // Cosine spacing in arc length from the trailing edge (i = 0) round the
                    // upper surface to the leading edge (i = half) and back along the lower.
                    let (j, upper) = if i <= half { (i, true) } else { (n - i, false) };
                    let s = 0.5 * total * (1.0 + (PI * j as f64 / half as f64).cos());
                    let u = match j {
                        0 => 1.0,
                        _ if j == half => 0.0,
                        _ => naca_u_at_arc(thickness, s),
                    };
                    let y = naca_half(thickness, u).0;
                    let nu = upper_normal(u);
                    let wp = if i == 0 {
                        let (up, low) = (nu, [nu[0], -nu[1]]);
                        WallPoint {
                            p: [1.0, 0.0],
                            n: normalised([up[0] + low[0], up[1] + low[1]]),
                        }
                    } else if upper {
                        WallPoint {
                            p: [u * u, y],
                            n: nu,
                        }
                    } else {
                        WallPoint {
                            p: [u * u, -y],
                            n: [nu[0], -nu[1]],
                        }
                    };
                    out.push(wp);
                }
                out
            }
        }
    }
}

/// Golden-section minimum of `f` on [lo, hi].
pub(super) fn golden(mut lo: f64, mut hi: f64, f: &impl Fn(f64) -> f64) -> f64 {
    let r = 0.5 * (5f64.sqrt() - 1.0);
    let mut a = hi - r * (hi - lo);
    let mut b = lo + r * (hi - lo);
    let (mut fa, mut fb) = (f(a), f(b));
    for _ in 0..120 {
        if fa < fb {
            hi = b;
            b = a;
            fb = fa;
            a = hi - r * (hi - lo);
            fa = f(a);
        } else {
            lo = a;
            a = b;
            fa = fb;
            b = lo + r * (hi - lo);
            fb = f(b);
        }
        if hi - lo <= 4.0 * f64::EPSILON * hi.abs().max(1.0) {
            break;
        }
    }
    // The bracket ends are candidates too (the minimum may sit at a corner).
    [lo, 0.5 * (lo + hi), hi]
        .into_iter()
        .map(|t| (f(t), t))
        .fold((f64::INFINITY, lo), |a, b| if b.0 < a.0 { b } else { a })
        .1
}
