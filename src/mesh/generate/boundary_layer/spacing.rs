//! Distances of the grid nodes along a wall-normal line, and the blend weights into the far
//! field.
//!
//! Input: first cell height, growth ratio, cells across, the distance to cover and the wall's
//! mean spacing. Output: a [`WallNormalSpacing`] whose first `geometric_cells` heights grow
//! geometrically from `first_height`; blend weights that are 0 over those cells and rise
//! smoothly to 1 at the far field.

use super::{GenerateError, bad};

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
pub(super) fn blend_weights(s: &WallNormalSpacing, by_index: bool) -> Vec<f64> {
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
