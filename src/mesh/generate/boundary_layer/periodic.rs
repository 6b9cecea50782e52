//! Periodic boundary-layer meshes: a streamwise-periodic channel over a bump and a rotational
//! sector of an annulus.
//!
//! Inputs: a [`BoundaryLayer`] (`around` cells along the period, `across` cells wall to wall,
//! first cell height, growth, extrusion layers and span) and the bump height or the sector
//! angle. Outputs: an oriented [`LinearMesh`] with named tags and the periodic pair
//! [`CHANNEL_PAIR`] or [`SECTOR_PAIR`] (`master:image` boundary names), whose transform the caller finds and
//! verifies with [`crate::mesh::periodic::resolve`].
//!
//! * [`channel`]: 0 ≤ x ≤ 1 (the period), from the wall y = b·sin²(πx) (`bump` b, smooth and
//!   periodic) to the flat top y = 1. Tags 1 `wall`, 2 `top`, 3 `periodic_left` (x = 0),
//!   4 `periodic_right` (x = 1, the image under the translation (1, 0, 0)); extruded: `zmin`,
//!   `zmax`. Grid lines are vertical; node j of a line sits at y_w + d_j·(1 − y_w) with d_j the
//!   wall-normal spacing over distance 1, so the first cell is `first_height` high where the
//!   wall is flat and (1 − b) times that on the crest.
//! * [`sector`]: the annulus between the hub r = 1 and the shroud r = 2, 0 ≤ θ ≤ `degrees`,
//!   graded to both walls (the spacing over half the gap, mirrored: `across` even). Tags 1
//!   `periodic_lo` (θ = 0), 2 `periodic_hi` (θ = `degrees`, the image under the rotation
//!   about z), 3 `hub`, 4 `shroud`; extruded along z: `zmin`, `zmax`.
//!
//! Invariants: wall vertices lie on the analytic wall (to rounding); the image side's vertices
//! are the transform of the master side's to rounding; every element is positively oriented
//! (else [`GenerateError::Invalid`]).

use super::{BoundaryLayer, BoundaryLayerMesh, GenerateError, assemble, bad, wall_normal_spacing};

/// The periodic pair of [`channel`], `master:image`.
pub const CHANNEL_PAIR: &str = "periodic_left:periodic_right";
/// The periodic pair of [`sector`], `master:image`.
pub const SECTOR_PAIR: &str = "periodic_lo:periodic_hi";

fn check(p: &BoundaryLayer) -> Result<(), GenerateError> {
    if p.around < 2 || p.around > 1 << 20 {
        return Err(bad("around", p.around, "must be in 2..=2^20"));
    }
    if p.across > 1 << 20 || p.layers > 1 << 16 {
        return Err(bad(
            "across",
            p.across,
            "too many cells (limits: 2^20 across, 2^16 layers)",
        ));
    }
    if p.layers > 0 && !(p.span > 0.0 && p.span.is_finite()) {
        return Err(bad("span", p.span, "must be positive"));
    }
    Ok(())
}

/// Structured grid of `ni + 1` × `nj + 1` points `point(i, j)`; the boundary lines j = 0,
/// j = nj, i = 0, i = ni tagged 1, 2, 3, 4.
fn grid(
    ni: usize,
    nj: usize,
    point: impl Fn(usize, usize) -> [f64; 3],
) -> (Vec<[f64; 3]>, Vec<u32>, Vec<u32>, Vec<i32>) {
    let id = |i: usize, j: usize| (j * (ni + 1) + i) as u32;
    let mut coords = Vec::with_capacity((ni + 1) * (nj + 1));
    for j in 0..=nj {
        for i in 0..=ni {
            coords.push(point(i, j));
        }
    }
    let mut elements = Vec::with_capacity(4 * ni * nj);
    for j in 0..nj {
        for i in 0..ni {
            elements.extend([id(i, j), id(i + 1, j), id(i + 1, j + 1), id(i, j + 1)]);
        }
    }
    let (mut facets, mut tags) = (Vec::new(), Vec::new());
    for i in 0..ni {
        facets.extend([id(i, 0), id(i + 1, 0), id(i, nj), id(i + 1, nj)]);
        tags.extend([1, 2]);
    }
    for j in 0..nj {
        facets.extend([id(0, j), id(0, j + 1), id(ni, j), id(ni, j + 1)]);
        tags.extend([3, 4]);
    }
    (coords, elements, facets, tags)
}

/// The periodic channel over the bump y = `bump`·sin²(πx) (module documentation).
pub fn channel(p: &BoundaryLayer, bump: f64) -> Result<BoundaryLayerMesh, GenerateError> {
    check(p)?;
    if !(0.0..0.5).contains(&bump) {
        return Err(bad(
            "bump",
            bump,
            "the bump height must be in [0, 0.5) of the channel height",
        ));
    }
    let cap = 1.0 / p.around as f64;
    let spacing = wall_normal_spacing(p.first_height, p.growth, p.across, 1.0, cap)?;
    let d = &spacing.distances;
    let (coords, elements, facets, tags) = grid(p.around, p.across, |i, j| {
        let x = i as f64 / p.around as f64;
        // x = 1 from the same formula as x = 0 plus the period, so the sides are images.
        let yw = bump * (std::f64::consts::PI * x).sin().powi(2);
        let yw = if i == p.around { 0.0 } else { yw };
        [x, yw + d[j] * (1.0 - yw), 0.0]
    });
    let names = ["wall", "top", "periodic_left", "periodic_right"];
    let mesh = assemble(coords, elements, facets, tags, &names, p)?;
    Ok(BoundaryLayerMesh { mesh, spacing })
}

/// The annular sector between the hub r = 1 and the shroud r = 2 over `degrees` (module
/// documentation).
pub fn sector(p: &BoundaryLayer, degrees: f64) -> Result<BoundaryLayerMesh, GenerateError> {
    check(p)?;
    if !(degrees > 0.0 && degrees <= 180.0) {
        return Err(bad(
            "sector",
            degrees,
            "the sector angle must be in (0, 180] degrees",
        ));
    }
    if !p.across.is_multiple_of(2) || p.across < 4 {
        return Err(bad(
            "across",
            p.across,
            "the sector is graded to both walls: give an even number of cells, at least 4",
        ));
    }
    let half = p.across / 2;
    let theta = degrees.to_radians();
    let cap = 1.5 * theta / p.around as f64;
    let spacing = wall_normal_spacing(p.first_height, p.growth, half, 0.5, cap)?;
    let d = &spacing.distances;
    // Grid lines i run outwards and j along θ (counter-clockwise cells): line j = 0 is the
    // side θ = 0, i = 0 the hub.
    let (coords, elements, facets, tags) = grid(p.across, p.around, |i, j| {
        let r = if i <= half {
            1.0 + d[i]
        } else {
            2.0 - d[p.across - i]
        };
        let t = theta * j as f64 / p.around as f64;
        let (s, c) = if j == 0 { (0.0, 1.0) } else { t.sin_cos() };
        [r * c, r * s, 0.0]
    });
    let names = ["periodic_lo", "periodic_hi", "hub", "shroud"];
    let mesh = assemble(coords, elements, facets, tags, &names, p)?;
    Ok(BoundaryLayerMesh { mesh, spacing })
}
