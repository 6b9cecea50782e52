//! Structured boundary-layer meshes around an analytic wall, the standard CFD layouts that
//! stress curving: O-grids around an ellipse, a circle or a symmetric NACA 00xx airfoil, and
//! C-grids around the airfoil with a wake cut.
//!
//! Inputs: a [`BoundaryLayer`] (wall, cells around and across, first cell height, growth ratio,
//! far-field radius, extrusion layers and span). Outputs: an oriented [`LinearMesh`] (2D quads,
//! or hexes when `layers ≥ 1`) with named boundary tags — 1 `wall`, 2 `farfield`, 3 `outflow`
//! (C-grid only), then `zmin`/`zmax` for extrusions — and the wall-normal spacing it used.
//!
//! Geometry and units. The ellipse has semi-axes 1 and `thickness` (chord 2, centred at the
//! origin), the circle radius 1 (chord 2); the NACA airfoil has chord 1 from the leading edge
//! at (0, 0) to the trailing edge at (1, 0) and the closed-trailing-edge thickness formula
//! (last coefficient −0.1036), so its trailing edge is a sharp corner. Lengths (first height)
//! are absolute, in these units; the far field radius is `farfield × chord`.
//!
//! Invariants. Wall vertices are points of the analytic wall ([`Wall::point`], exact up to
//! rounding); the grid line leaving a wall vertex is the straight offset along the wall's unit
//! normal (the bisector at the O-grid's trailing edge, the lower/upper surface normal on either
//! side of the C-grid's trailing edge) for as long as the cells grow geometrically, so the first
//! cell height is `first_height` and the height ratio of consecutive cells is `growth` there
//! ([`WallNormalSpacing`]). Beyond it the lines blend smoothly (Hermite weight of the layer
//! index for the O-grid, of the distance for the C-grid) into the far field: for the O-grid in
//! polar coordinates about the wall's centre onto the circle of radius `farfield × chord`
//! (points equally spaced in angle); for the C-grid in Cartesian coordinates onto a half circle
//! about the trailing edge continued downstream by the lines y = ±R to the outflow x = 1 + R
//! (R = `farfield` chords). Every element has positive corner Jacobians, or the
//! generator returns an error naming the element (it does not for the documented option ranges;
//! the tests sweep them).
//!
//! Points around the wall: uniform in the parameter angle θ of (cos θ, t·sin θ) for the ellipse
//! and the circle; cosine spacing in arc length on each airfoil surface (clustered at the leading
//! and trailing edges) for the airfoil.

use super::{extrude, uniform};
use crate::mesh::{LinearMesh, MeshOptions};
use std::f64::consts::PI;

/// Problems with the options of a boundary-layer mesh.
#[derive(Debug, thiserror::Error)]
pub enum GenerateError {
    #[error("--{option} {value}: {problem}")]
    Option {
        option: &'static str,
        value: String,
        problem: String,
    },
    #[error("generated element {element} is {what}; {hint}")]
    Invalid {
        element: u32,
        what: &'static str,
        hint: &'static str,
    },
}

fn bad(option: &'static str, value: impl ToString, problem: impl Into<String>) -> GenerateError {
    GenerateError::Option {
        option,
        value: value.to_string(),
        problem: problem.into(),
    }
}

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

/// `--wall ellipse|circle|naca`, each with its default thickness.
impl clap::ValueEnum for Wall {
    fn value_variants<'a>() -> &'a [Self] {
        &[Wall::ELLIPSE, Wall::Circle, Wall::NACA_0012]
    }
    fn to_possible_value(&self) -> Option<clap::builder::PossibleValue> {
        use clap::builder::PossibleValue;
        Some(match self {
            Wall::Ellipse { .. } => {
                PossibleValue::new("ellipse").help("Semi-axes 1 and `--thickness` (chord 2)")
            }
            Wall::Circle => PossibleValue::new("circle").help("Radius 1 (chord 2)"),
            Wall::Naca { .. } => PossibleValue::new("naca")
                .help("NACA 00xx of chord 1, thickness `--thickness`, closed trailing edge"),
        })
    }
}

/// NACA 4-digit half thickness in the parameter u = √x, and its u-derivative.
fn naca_half(t: f64, u: f64) -> (f64, f64) {
    let (u2, u3) = (u * u, u * u * u);
    let (u4, u5) = (u2 * u2, u2 * u3);
    let y = 5.0 * t * (0.2969 * u - 0.126 * u2 - 0.3516 * u4 + 0.2843 * u4 * u2 - 0.1036 * u4 * u4);
    let dy = 5.0 * t * (0.2969 - 0.252 * u - 1.4064 * u3 + 1.7058 * u5 - 0.8288 * u5 * u2);
    (y, dy)
}

/// Arc length of the airfoil's upper surface from the leading edge to parameter u = √x
/// (5-point Gauss–Legendre on 64 panels; the integrand √(4u² + y'(u)²) is smooth in u).
fn naca_arc(t: f64, u: f64) -> f64 {
    const X: [f64; 5] = [
        -0.906_179_845_938_664,
        -0.538_469_310_105_683,
        0.0,
        0.538_469_310_105_683,
        0.906_179_845_938_664,
    ];
    const W: [f64; 5] = [
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
fn naca_u_at_arc(t: f64, s: f64) -> f64 {
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

fn normalised(v: [f64; 2]) -> [f64; 2] {
    let l = v[0].hypot(v[1]);
    [v[0] / l, v[1] / l]
}

/// A wall vertex and the unit direction of the grid line leaving it.
#[derive(Clone, Copy, Debug)]
struct WallPoint {
    p: [f64; 2],
    n: [f64; 2],
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
    fn check(&self) -> Result<(), GenerateError> {
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
    fn vertices(&self, n: usize) -> Vec<WallPoint> {
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
fn golden(mut lo: f64, mut hi: f64, f: &impl Fn(f64) -> f64) -> f64 {
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

/// Options of a boundary-layer mesh (see the module documentation for units).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BoundaryLayer {
    pub wall: Wall,
    /// Cells around the wall (even for the airfoil).
    pub around: usize,
    /// Cells from the wall to the far field (≥ 2).
    pub across: usize,
    /// Height of the first cell off the wall (absolute, in wall units).
    pub first_height: f64,
    /// Height ratio of consecutive cells in the near-wall region (≥ 1).
    pub growth: f64,
    /// Far-field radius in chords.
    pub farfield: f64,
    /// 0: 2D quads; L ≥ 1: L hex layers extruded along z over `span`.
    pub layers: usize,
    /// Extrusion length along z.
    pub span: f64,
    /// C-grid: cells along the wake cut (each side).
    pub wake: usize,
}

impl Default for BoundaryLayer {
    fn default() -> Self {
        BoundaryLayer {
            wall: Wall::Ellipse { thickness: 0.2 },
            around: 128,
            across: 48,
            first_height: 1e-5,
            growth: 1.25,
            farfield: 10.0,
            layers: 0,
            span: 1.0,
            wake: 32,
        }
    }
}

/// Distances of the grid nodes from the wall along a wall-normal line.
#[derive(Clone, Debug, PartialEq)]
pub struct WallNormalSpacing {
    /// `across + 1` increasing distances from 0 to the far-field distance.
    pub distances: Vec<f64>,
    /// Cells from the wall with heights `first · growth^k` exactly (k < `geometric_cells`).
    pub geometric_cells: usize,
    /// Height ratio of the remaining cells (≥ 1), which stretch to the far field.
    pub outer_growth: f64,
}

/// Wall-normal node distances: `cells` cells, the first `first` high, growing by `growth`
/// until a cell reaches `cap` (the mean spacing around the wall, so cells there are about
/// square) or the remaining cells could not grow any more; the rest grow geometrically by
/// whatever ratio q ≥ 1 ends them exactly at `distance`. So the geometric series neither
/// overshoots (growth stops, the outer cells are nearly uniform) nor undershoots (the outer
/// cells stretch faster than `growth`) the far field.
pub fn wall_normal_spacing(
    first: f64,
    growth: f64,
    cells: usize,
    distance: f64,
    cap: f64,
) -> Result<WallNormalSpacing, GenerateError> {
    if cells < 2 {
        return Err(bad(
            "across",
            cells,
            "need at least 2 cells from the wall to the far field",
        ));
    }
    if !(first > 0.0 && first.is_finite()) {
        return Err(bad("first-height", first, "must be positive"));
    }
    if !(growth >= 1.0 && growth.is_finite()) {
        return Err(bad("growth", growth, "the growth ratio must be at least 1"));
    }
    if first * cells as f64 > distance {
        return Err(bad(
            "first-height",
            first,
            format!(
                "{cells} cells of this height already reach past the far field \
                 ({distance} from the wall)"
            ),
        ));
    }
    // Largest geometric region allowed by the cap, the far field and q ≥ 1.
    let mut heights = Vec::new();
    let mut sum = 0.0;
    let mut h = first;
    while heights.len() < cells - 1 && (heights.is_empty() || h <= cap) {
        heights.push(h);
        sum += h;
        h *= growth;
    }
    loop {
        let k = heights.len();
        let rem = distance - sum;
        if k == 1 || ((cells - k) as f64) * heights[k - 1] <= rem {
            break;
        }
        sum -= heights.pop().unwrap();
    }
    let k = heights.len();
    let n = cells - k;
    let last = heights[k - 1];
    let rem = distance - sum;
    let outer = |q: f64| {
        let mut s = 0.0;
        let mut p = 1.0;
        for _ in 0..n {
            p *= q;
            s += p;
        }
        last * s
    };
    let (mut lo, mut hi) = (1.0, 2.0);
    while outer(hi) < rem {
        lo = hi;
        hi *= 2.0;
    }
    for _ in 0..200 {
        let mid = 0.5 * (lo + hi);
        if outer(mid) < rem {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    let q = 0.5 * (lo + hi);
    let mut distances = Vec::with_capacity(cells + 1);
    let mut d = 0.0;
    distances.push(d);
    for h in &heights {
        d += h;
        distances.push(d);
    }
    let mut h = last;
    for _ in 0..n {
        h *= q;
        d += h;
        distances.push(d);
    }
    distances[cells] = distance;
    Ok(WallNormalSpacing {
        distances,
        geometric_cells: k,
        outer_growth: q,
    })
}

/// Hermite blend weight of each layer: 0 through the geometric region (the lines are exact
/// wall-normal offsets there), rising smoothly to 1 at the far field, as a function of the
/// layer index (`by_index`) or of the distance from the wall. The O-grid blends by index: its
/// outer cells are long, and a weight of the distance would leave the lines still turning in
/// the last layers, skewing the largest cells. The C-grid's Cartesian blend moves points by
/// up to a chord or more, which is only safe once the offset itself is that far out: it blends
/// by distance.
fn blend_weights(s: &WallNormalSpacing, by_index: bool) -> Vec<f64> {
    let k0 = s.geometric_cells;
    let d = &s.distances;
    let m = d.len() - 1;
    (0..=m)
        .map(|k| {
            if k <= k0 {
                0.0
            } else {
                let t = if by_index {
                    (k - k0) as f64 / (m - k0) as f64
                } else {
                    (d[k] - d[k0]) / (d[m] - d[k0])
                };
                let t = t.clamp(0.0, 1.0);
                t * t * (3.0 - 2.0 * t)
            }
        })
        .collect()
}

/// A generated boundary-layer mesh and the wall-normal spacing it used.
#[derive(Clone, Debug)]
pub struct BoundaryLayerMesh {
    pub mesh: LinearMesh,
    pub spacing: WallNormalSpacing,
}

fn check_common(p: &BoundaryLayer) -> Result<(), GenerateError> {
    p.wall.check()?;
    if !(p.farfield.is_finite() && p.farfield > 1.0) {
        return Err(bad(
            "farfield",
            p.farfield,
            "the far field must be more than 1 chord away",
        ));
    }
    if p.layers > 0 && !(p.span > 0.0 && p.span.is_finite()) {
        return Err(bad("span", p.span, "must be positive"));
    }
    if p.around > 1 << 20 || p.across > 1 << 20 || p.wake > 1 << 20 || p.layers > 1 << 16 {
        return Err(bad(
            "around",
            p.around,
            "too many cells (limits: 2^20 around/across/wake, 2^16 layers)",
        ));
    }
    Ok(())
}

/// Mean spacing of consecutive points.
fn mean_spacing(points: &[[f64; 2]]) -> f64 {
    let total: f64 = points
        .windows(2)
        .map(|w| (w[1][0] - w[0][0]).hypot(w[1][1] - w[0][1]))
        .sum();
    total / (points.len() - 1) as f64
}

/// O-grid around `p.wall`: `around × across` quads (times `layers` hexes).
pub fn ogrid(p: &BoundaryLayer) -> Result<BoundaryLayerMesh, GenerateError> {
    check_common(p)?;
    let n = p.around;
    let naca = matches!(p.wall, Wall::Naca { .. });
    if n < 4 || (naca && n % 2 == 1) {
        return Err(bad(
            "around",
            n,
            "need at least 4 cells around the wall (an even number for the airfoil)",
        ));
    }
    let wall = p.wall.vertices(n);
    let c = p.wall.centre();
    let radius = p.farfield * p.wall.chord();
    let r_wall = wall
        .iter()
        .map(|w| (w.p[0] - c[0]).hypot(w.p[1] - c[1]))
        .fold(0.0, f64::max);
    // At this distance no offset point is outside the far-field circle.
    let distance = radius - r_wall;
    let mut closed: Vec<[f64; 2]> = wall.iter().map(|w| w.p).collect();
    closed.push(wall[0].p);
    let spacing = wall_normal_spacing(
        p.first_height,
        p.growth,
        p.across,
        distance,
        mean_spacing(&closed),
    )?;
    let blend = blend_weights(&spacing, true);
    let m = p.across;
    let mut coords = Vec::with_capacity(n * (m + 1));
    for (k, (&d, &b)) in spacing.distances.iter().zip(&blend).enumerate() {
        for (i, w) in wall.iter().enumerate() {
            let a = [w.p[0] + d * w.n[0], w.p[1] + d * w.n[1]];
            let phi = 2.0 * PI * i as f64 / n as f64;
            let q = if k == m {
                [c[0] + radius * phi.cos(), c[1] + radius * phi.sin()]
            } else if b == 0.0 {
                a
            } else {
                // Polar blend about the centre: every offset curve is convex round it.
                let rel = [a[0] - c[0], a[1] - c[1]];
                let r = rel[0].hypot(rel[1]);
                let alpha = rel[1].atan2(rel[0]);
                let turn = (phi - alpha + PI).rem_euclid(2.0 * PI) - PI;
                let alpha = alpha + b * turn;
                let r = (1.0 - b) * r + b * radius;
                [c[0] + r * alpha.cos(), c[1] + r * alpha.sin()]
            };
            coords.push([q[0], q[1], 0.0]);
        }
    }
    let id = |i: usize, k: usize| (k * n + i % n) as u32;
    let mut elements = Vec::with_capacity(4 * n * m);
    for k in 0..m {
        for i in 0..n {
            // i runs counter-clockwise, k outward: (k, i) is the positive frame.
            elements.extend([id(i, k), id(i, k + 1), id(i + 1, k + 1), id(i + 1, k)]);
        }
    }
    let mut tagged_facets = Vec::new();
    let mut facet_tags = Vec::new();
    for i in 0..n {
        tagged_facets.extend([id(i, 0), id(i + 1, 0)]);
        facet_tags.push(1);
        tagged_facets.extend([id(i, m), id(i + 1, m)]);
        facet_tags.push(2);
    }
    let mesh = assemble(
        coords,
        elements,
        tagged_facets,
        facet_tags,
        &["wall", "farfield"],
        p,
    )?;
    Ok(BoundaryLayerMesh { mesh, spacing })
}

/// C-grid around a NACA 00xx airfoil with a wake cut along y = 0 from the trailing edge to the
/// outflow x = 1 + R (R = `farfield` chords): `(2·wake + around) × across` quads. The cut is
/// interior: its nodes are shared by the lower and the upper half.
pub fn cgrid(p: &BoundaryLayer) -> Result<BoundaryLayerMesh, GenerateError> {
    check_common(p)?;
    let Wall::Naca { thickness } = p.wall else {
        return Err(bad(
            "wall",
            format!("{:?}", p.wall),
            "a C-grid needs the airfoil wall (--wall naca)",
        ));
    };
    let n = p.around;
    if n < 4 || n % 2 == 1 {
        return Err(bad(
            "around",
            n,
            "need an even number, at least 4, of cells around the airfoil",
        ));
    }
    let nw = p.wake;
    if nw < 1 {
        return Err(bad("wake", nw, "need at least 1 cell along the wake"));
    }
    let radius = p.farfield * p.wall.chord();
    let o = p.wall.vertices(n);
    // Clockwise from the trailing edge: lower surface, leading edge, upper surface.
    let mut wall: Vec<WallPoint> = (0..=n).map(|j| o[(n - j) % n]).collect();
    // One-sided surface normals at the trailing edge: the lines there start wall-normal.
    let tilt = normalised([-naca_half(thickness, 1.0).1, 2.0]);
    wall[0].n = [tilt[0], -tilt[1]];
    wall[n].n = tilt;
    // Wake points from the trailing edge: first cell as long as the wall cell next to the
    // trailing edge, geometric to the outflow.
    let h_te = (o[1].p[0] - o[0].p[0]).hypot(o[1].p[1] - o[0].p[1]);
    let wake_len = radius;
    let ratio = {
        let total = |q: f64| (0..nw).map(|l| h_te * q.powi(l as i32)).sum::<f64>();
        let (mut lo, mut hi) = (1e-6, 2.0);
        while total(hi) < wake_len {
            lo = hi;
            hi *= 2.0;
        }
        for _ in 0..200 {
            let mid = 0.5 * (lo + hi);
            if total(mid) < wake_len {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        0.5 * (lo + hi)
    };
    let mut wake_x = Vec::with_capacity(nw + 1);
    let mut x = 1.0;
    for l in 0..nw {
        wake_x.push(x);
        x += h_te * ratio.powi(l as i32);
    }
    wake_x.push(1.0 + wake_len);
    // Wake lines lean downstream like the trailing-edge normal, straightening linearly to the
    // outflow, so neighbouring lines never converge within the far field.
    let lean = |x: f64| {
        let s = ((x - 1.0) / wake_len).clamp(0.0, 1.0);
        let g = tilt[0].atan2(tilt[1]) * (1.0 - s);
        [g.sin(), g.cos()]
    };
    // Inner C-line i = 0..=ni with directions and far-field targets.
    let ni = 2 * nw + n;
    let mut line = Vec::with_capacity(ni + 1);
    let mut target = Vec::with_capacity(ni + 1);
    for i in 0..=ni {
        if i < nw {
            let x = wake_x[nw - i];
            let l = lean(x);
            line.push(WallPoint {
                p: [x, 0.0],
                n: [l[0], -l[1]],
            });
            target.push([x, -radius]);
        } else if i <= nw + n {
            let j = i - nw;
            line.push(wall[j]);
            let beta = -0.5 * PI - PI * j as f64 / n as f64;
            target.push(match j {
                0 => [1.0, -radius],
                _ if j == n => [1.0, radius],
                _ => [1.0 + radius * beta.cos(), radius * beta.sin()],
            });
        } else {
            let x = wake_x[i - nw - n];
            line.push(WallPoint {
                p: [x, 0.0],
                n: lean(x),
            });
            target.push([x, radius]);
        }
    }
    // The leading edge's offset reaches the half circle exactly at this distance.
    let distance = radius - 1.0;
    let wall_points: Vec<[f64; 2]> = wall.iter().map(|w| w.p).collect();
    let spacing = wall_normal_spacing(
        p.first_height,
        p.growth,
        p.across,
        distance,
        mean_spacing(&wall_points),
    )?;
    let blend = blend_weights(&spacing, false);
    let m = p.across;
    // Node ids: the upper wake's cut nodes are the lower wake's.
    let mut ids = vec![u32::MAX; (ni + 1) * (m + 1)];
    let mut coords = Vec::new();
    for k in 0..=m {
        let (d, b) = (spacing.distances[k], blend[k]);
        for i in 0..=ni {
            if k == 0 && i >= nw + n {
                ids[i] = ids[2 * nw + n - i];
                continue;
            }
            let w = line[i];
            let end = [w.p[0] + distance * w.n[0], w.p[1] + distance * w.n[1]];
            let q = if k == m {
                target[i]
            } else {
                let a = [w.p[0] + d * w.n[0], w.p[1] + d * w.n[1]];
                [
                    a[0] + b * (target[i][0] - end[0]),
                    a[1] + b * (target[i][1] - end[1]),
                ]
            };
            ids[k * (ni + 1) + i] = coords.len() as u32;
            coords.push([q[0], q[1], 0.0]);
        }
    }
    let id = |i: usize, k: usize| ids[k * (ni + 1) + i];
    let mut elements = Vec::with_capacity(4 * ni * m);
    for k in 0..m {
        for i in 0..ni {
            // i runs clockwise round the airfoil, k outward: (i, k) is the positive frame.
            elements.extend([id(i, k), id(i + 1, k), id(i + 1, k + 1), id(i, k + 1)]);
        }
    }
    let mut tagged_facets = Vec::new();
    let mut facet_tags = Vec::new();
    for i in nw..nw + n {
        tagged_facets.extend([id(i, 0), id(i + 1, 0)]);
        facet_tags.push(1);
    }
    for i in 0..ni {
        tagged_facets.extend([id(i, m), id(i + 1, m)]);
        facet_tags.push(2);
    }
    for k in 0..m {
        tagged_facets.extend([id(0, k), id(0, k + 1), id(ni, k), id(ni, k + 1)]);
        facet_tags.extend([3, 3]);
    }
    let mesh = assemble(
        coords,
        elements,
        tagged_facets,
        facet_tags,
        &["wall", "farfield", "outflow"],
        p,
    )?;
    Ok(BoundaryLayerMesh { mesh, spacing })
}

/// Check, extrude when asked, and name the tags (1.. in order, then `zmin`, `zmax`).
fn assemble(
    coords: Vec<[f64; 3]>,
    elements: Vec<u32>,
    tagged_facets: Vec<u32>,
    facet_tags: Vec<i32>,
    names: &[&str],
    p: &BoundaryLayer,
) -> Result<LinearMesh, GenerateError> {
    let mut mesh = LinearMesh {
        dim: 2,
        coords,
        elements,
        tagged_facets,
        facet_tags,
        ..Default::default()
    };
    check_orientation(&mut mesh)?;
    if p.layers > 0 {
        mesh = extrude(&mesh, &uniform(p.layers, p.span / p.layers as f64));
        check_orientation(&mut mesh)?;
    }
    for (t, name) in names.iter().enumerate() {
        mesh.tag_names.insert(t as i32 + 1, (*name).into());
    }
    if p.layers > 0 {
        let top = names.len() as i32;
        mesh.tag_names.insert(top + 1, "zmin".into());
        mesh.tag_names.insert(top + 2, "zmax".into());
    }
    Ok(mesh)
}

/// Every element must already be positively oriented: a flip would hide a generator bug.
fn check_orientation(mesh: &mut LinearMesh) -> Result<(), GenerateError> {
    let before = mesh.reoriented;
    mesh.normalise_orientation(&MeshOptions::default(), &[])
        .map_err(|_| {
            let (_, e) = mesh.min_scaled_jacobian().unwrap_or((0.0, 0));
            GenerateError::Invalid {
                element: e as u32,
                what: "tangled or degenerate",
                hint: "try fewer cells across, a smaller growth ratio or a larger far field",
            }
        })?;
    if mesh.reoriented != before {
        let (_, e) = mesh.min_scaled_jacobian().unwrap_or((0.0, 0));
        return Err(GenerateError::Invalid {
            element: e as u32,
            what: "inverted",
            hint: "try fewer cells across, a smaller growth ratio or a larger far field",
        });
    }
    Ok(())
}

/// Largest element aspect ratio: longest over shortest edge of each element.
pub fn max_aspect_ratio(mesh: &LinearMesh) -> f64 {
    let edges: &[[usize; 2]] = if mesh.dim == 2 {
        &[[0, 1], [1, 2], [2, 3], [3, 0]]
    } else {
        &[
            [0, 1],
            [1, 2],
            [2, 3],
            [3, 0],
            [4, 5],
            [5, 6],
            [6, 7],
            [7, 4],
            [0, 4],
            [1, 5],
            [2, 6],
            [3, 7],
        ]
    };
    let npe = mesh.nodes_per_element();
    mesh.elements
        .chunks(npe)
        .map(|e| {
            let (mut lo, mut hi) = (f64::INFINITY, 0.0f64);
            for [a, b] in edges {
                let (p, q) = (mesh.coords[e[*a] as usize], mesh.coords[e[*b] as usize]);
                let l =
                    ((p[0] - q[0]).powi(2) + (p[1] - q[1]).powi(2) + (p[2] - q[2]).powi(2)).sqrt();
                lo = lo.min(l);
                hi = hi.max(l);
            }
            hi / lo
        })
        .fold(0.0, f64::max)
}
