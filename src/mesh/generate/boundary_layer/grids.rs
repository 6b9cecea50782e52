//! The two layouts: the O-grid around any wall and the C-grid around the airfoil with a wake
//! cut.
//!
//! Input: checked [`BoundaryLayer`] options. Output: the quad grid's coordinates, elements and
//! tagged boundary facets, handed to [`assemble`](super::assemble) for the orientation check,
//! the extrusion and the tag names. Invariant: the grid line leaving each wall vertex is its
//! straight wall-normal offset over the geometric cells, then blends into the far field.

use super::spacing::{WallNormalSpacing, blend_weights, wall_normal_spacing};
use super::wall::{WallPoint, naca_half, normalised};
use super::{
    BoundaryLayer, BoundaryLayerMesh, GenerateError, Wall, assemble, bad, check_common,
    mean_spacing,
};
use std::f64::consts::PI;

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
    let wake_x = wake_stations(h_te, nw, wake_len);
    let c = CLine::new(&wall, &wake_x, tilt, n, radius);
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
    let (ids, coords) = c.nodes(&spacing, &blend, distance, nw, n);
    let ni = c.line.len() - 1;
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

/// x of the wake nodes from the trailing edge (x = 1) to the outflow (x = 1 + `wake_len`):
/// the first cell `h_te` long, the others growing geometrically.
fn wake_stations(h_te: f64, nw: usize, wake_len: f64) -> Vec<f64> {
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
    wake_x
}

/// The inner C-line: wake nodes of the lower cut (outflow to trailing edge), the wall
/// clockwise, the upper cut's wake nodes; each with the direction its grid line leaves in and
/// the far-field point it ends at.
struct CLine {
    line: Vec<WallPoint>,
    target: Vec<[f64; 2]>,
}

impl CLine {
    fn new(wall: &[WallPoint], wake_x: &[f64], tilt: [f64; 2], n: usize, radius: f64) -> CLine {
        let nw = wake_x.len() - 1;
        let wake_len = radius;
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
        CLine { line, target }
    }

    /// Node ids on the `(ni + 1) × (m + 1)` grid and the coordinates; the upper wake's cut
    /// nodes are the lower wake's.
    fn nodes(
        &self,
        spacing: &WallNormalSpacing,
        blend: &[f64],
        distance: f64,
        nw: usize,
        n: usize,
    ) -> (Vec<u32>, Vec<[f64; 3]>) {
        let (line, target) = (&self.line, &self.target);
        let ni = line.len() - 1;
        let m = spacing.distances.len() - 1;
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
        (ids, coords)
    }
}
