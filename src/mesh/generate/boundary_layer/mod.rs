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
//!
//! Parts: `wall` (the analytic walls), `spacing` (distances along a wall-normal line and
//! the far-field blend), `grids` (the O- and C-grid layouts), `periodic` (the periodic
//! channel and annular sector); this module checks the options
//! and assembles, extrudes and checks the mesh.

mod grids;
mod periodic;
mod spacing;
mod wall;

pub use grids::{cgrid, ogrid};
pub use periodic::{CHANNEL_PAIR, SECTOR_PAIR, channel, sector};
pub use spacing::{WallNormalSpacing, wall_normal_spacing};
pub use wall::Wall;

use super::{extrude, uniform};
use crate::mesh::{LinearMesh, MeshOptions};

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
