//! SVG drawings of 2D meshes: curved element edges drawn as curves, with optional overlays
//! (a second mesh, the linear input, control points), as in the paper's Figs. 1–2.
//!
//! Input: layers of [`HighOrderMesh`]es (a linear mesh is an order-1 one) and point sets.
//! Output: one SVG document, y axis pointing up, scaled to the union of the layers.

use crate::math::lagrange::lagrange_1d;
use crate::mesh::HighOrderMesh;
use crate::params::{ParamError, num};
use std::fmt::Write;

/// `plot --width`: pixels in [16, 100000].
pub fn check_plot_width(width: f64) -> Result<(), ParamError> {
    if width.is_finite() && (16.0..=100_000.0).contains(&width) {
        Ok(())
    } else {
        Err(ParamError::new(
            "--width",
            num(width),
            "must be a number of pixels in [16, 100000]",
        ))
    }
}

/// `plot --label`: at most one per drawn mesh.
pub fn check_plot_labels(labels: usize, meshes: usize) -> Result<(), ParamError> {
    if labels <= meshes {
        Ok(())
    } else {
        Err(ParamError::new(
            "--label",
            format!("given {labels} times"),
            format!(
                "{meshes} meshes: give at most one label per mesh (MESH first, then each --overlay)"
            ),
        ))
    }
}

/// `plot --window X0,Y0,X1,Y1`: four finite numbers spanning a rectangle of non-zero size.
pub fn parse_window(text: &str) -> Result<[f64; 4], ParamError> {
    let v: Vec<f64> = text
        .split(',')
        .map(|x| x.trim().parse::<f64>())
        .collect::<Result<_, _>>()
        .map_err(|e| ParamError::new("--window", text, e.to_string()))?;
    match v[..] {
        [x0, y0, x1, y1] if x0 != x1 && y0 != y1 && v.iter().all(|x| x.is_finite()) => {
            Ok([x0, y0, x1, y1])
        }
        _ => Err(ParamError::new(
            "--window",
            text,
            "give four numbers X0,Y0,X1,Y1 of a rectangle of non-zero size",
        )),
    }
}

/// One thing to draw.
pub enum Layer<'a> {
    /// Element edges of a 2D mesh, in a colour, with a stroke width relative to the default.
    Mesh {
        mesh: &'a HighOrderMesh,
        colour: &'a str,
        width: f64,
        label: &'a str,
    },
    /// Points as small discs of `radius` pixels.
    Points {
        points: &'a [[f64; 3]],
        colour: &'a str,
        label: &'a str,
        radius: f64,
    },
}

/// Samples per element edge for curved drawing.
const SEGMENTS: usize = 16;

/// The polylines of every element edge of a 2D high-order mesh (each interior edge once).
pub fn edge_polylines(mesh: &HighOrderMesh) -> Vec<Vec<[f64; 2]>> {
    assert_eq!(mesh.dim, 2, "plots are 2D");
    let p = mesh.order;
    let m = p + 1;
    let mut v = vec![0.0; m];
    let mut d = vec![0.0; m];
    let tables: Vec<Vec<f64>> = (0..=SEGMENTS)
        .map(|s| {
            lagrange_1d(p, s as f64 / SEGMENTS as f64, &mut v, &mut d);
            v.clone()
        })
        .collect();
    let mut seen = std::collections::HashSet::new();
    let mut lines = Vec::new();
    for e in 0..mesh.n_elements() {
        let nodes = mesh.element(e);
        // Edge node lists along the lattice: bottom, right, top, left.
        let edges: [Vec<u32>; 4] = [
            (0..m).map(|i| nodes[i]).collect(),
            (0..m).map(|j| nodes[p + m * j]).collect(),
            (0..m).map(|i| nodes[i + m * p]).collect(),
            (0..m).map(|j| nodes[m * j]).collect(),
        ];
        for edge in edges {
            let key = (
                edge[0].min(edge[p]),
                edge[0].max(edge[p]),
                edge[p / 2].min(edge[p.div_ceil(2)]),
            );
            if !seen.insert(key) {
                continue;
            }
            let line = tables
                .iter()
                .map(|w| {
                    let mut x = [0.0; 2];
                    for (k, &n) in edge.iter().enumerate() {
                        let q = mesh.nodes[n as usize];
                        x[0] += w[k] * q[0];
                        x[1] += w[k] * q[1];
                    }
                    x
                })
                .collect();
            lines.push(line);
        }
    }
    lines
}

/// Render layers to an SVG document `size` pixels wide, showing all of them.
pub fn render_svg(layers: &[Layer], size: f64) -> String {
    render_svg_window(layers, size, None, false)
}

/// Render layers to an SVG document `size` pixels wide. `window` ([x0, y0, x1, y1]) shows only
/// that rectangle (a zoom, as in the paper's Fig. 5), clipping what lies outside; `legend`
/// writes each labelled layer's label in its colour at the top left.
pub fn render_svg_window(
    layers: &[Layer],
    size: f64,
    window: Option<[f64; 4]>,
    legend: bool,
) -> String {
    let (mut lo, mut hi) = match window {
        Some([x0, y0, x1, y1]) => ([x0.min(x1), y0.min(y1)], [x0.max(x1), y0.max(y1)]),
        None => ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]),
    };
    let fixed = window.is_some();
    let mut grow = |x: &[f64]| {
        if fixed {
            return;
        }
        for k in 0..2 {
            lo[k] = lo[k].min(x[k]);
            hi[k] = hi[k].max(x[k]);
        }
    };
    let mut polylines: Vec<Vec<Vec<[f64; 2]>>> = Vec::new();
    for layer in layers {
        match layer {
            Layer::Mesh { mesh, .. } => {
                let lines = edge_polylines(mesh);
                for l in &lines {
                    for x in l {
                        grow(x);
                    }
                }
                polylines.push(lines);
            }
            Layer::Points { points, .. } => {
                for x in points.iter() {
                    grow(x);
                }
                polylines.push(Vec::new());
            }
        }
    }
    let span = (hi[0] - lo[0]).max(hi[1] - lo[1]).max(f64::MIN_POSITIVE);
    let margin = 0.03 * span;
    let scale = size / (span + 2.0 * margin);
    let w = (hi[0] - lo[0] + 2.0 * margin) * scale;
    let h = (hi[1] - lo[1] + 2.0 * margin) * scale;
    let tx = |x: &[f64]| {
        (
            (x[0] - lo[0] + margin) * scale,
            (hi[1] - x[1] + margin) * scale,
        )
    };
    let mut svg = String::new();
    let _ = writeln!(
        svg,
        "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"{w:.0}\" height=\"{h:.0}\" viewBox=\"0 0 {w:.2} {h:.2}\">"
    );
    let _ = writeln!(svg, "<rect width=\"100%\" height=\"100%\" fill=\"white\"/>");
    if fixed {
        // Clip to the window itself (not the margin around it).
        let _ = writeln!(
            svg,
            "<clipPath id=\"window\"><rect x=\"{m:.2}\" y=\"{m:.2}\" width=\"{:.2}\" height=\"{:.2}\"/></clipPath><g clip-path=\"url(#window)\">",
            w - 2.0 * margin * scale,
            h - 2.0 * margin * scale,
            m = margin * scale
        );
    }
    for (layer, lines) in layers.iter().zip(&polylines) {
        match layer {
            Layer::Mesh {
                colour,
                width,
                label,
                ..
            } => {
                let _ = writeln!(
                    svg,
                    "<g fill=\"none\" stroke=\"{colour}\" stroke-width=\"{:.3}\" stroke-linejoin=\"round\"><title>{label}</title>",
                    0.6 * width
                );
                for l in lines {
                    // Outside the window: leave it out rather than clip it.
                    let outside =
                        |k: usize| l.iter().all(|x| x[k] < lo[k]) || l.iter().all(|x| x[k] > hi[k]);
                    if fixed && (outside(0) || outside(1)) {
                        continue;
                    }
                    let pts: Vec<String> = l
                        .iter()
                        .map(|x| {
                            let (a, b) = tx(x);
                            format!("{a:.2},{b:.2}")
                        })
                        .collect();
                    let _ = writeln!(svg, "<polyline points=\"{}\"/>", pts.join(" "));
                }
                let _ = writeln!(svg, "</g>");
            }
            Layer::Points {
                points,
                colour,
                label,
                radius,
            } => {
                let _ = writeln!(svg, "<g fill=\"{colour}\"><title>{label}</title>");
                for x in points.iter() {
                    if fixed && (0..2).any(|k| x[k] < lo[k] || x[k] > hi[k]) {
                        continue;
                    }
                    let (a, b) = tx(x);
                    let _ = writeln!(
                        svg,
                        "<circle cx=\"{a:.2}\" cy=\"{b:.2}\" r=\"{radius:.2}\"/>"
                    );
                }
                let _ = writeln!(svg, "</g>");
            }
        }
    }
    if fixed {
        let _ = writeln!(svg, "</g>");
    }
    if legend {
        let mut y = 18.0;
        let mut seen = std::collections::HashSet::new();
        for layer in layers {
            let (colour, label) = match layer {
                Layer::Mesh { colour, label, .. } | Layer::Points { colour, label, .. } => {
                    (colour, label)
                }
            };
            if label.is_empty() || !seen.insert((*colour, *label)) {
                continue;
            }
            let _ = writeln!(
                svg,
                "<text x=\"10\" y=\"{y:.0}\" fill=\"{colour}\" font-family=\"sans-serif\" font-size=\"14\">{}</text>",
                escape(label)
            );
            y += 18.0;
        }
    }
    let _ = writeln!(svg, "</svg>");
    svg
}

/// Text content safe inside an SVG element.
fn escape(s: &str) -> String {
    s.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn window_width_and_labels_are_checked() {
        assert!(parse_window("0,0,1,1").is_ok());
        assert!(parse_window("0,0,0,1").is_err());
        assert!(parse_window("0,0,1").is_err());
        assert!(check_plot_width(f64::NAN).is_err());
        assert!(check_plot_labels(3, 2).is_err());
    }
}
