//! SVG drawings of 2D meshes: curved element edges drawn as curves, with optional overlays
//! (a second mesh, the linear input, control points), as in the paper's Figs. 1–2.
//!
//! Input: layers of [`HighOrderMesh`]es (a linear mesh is an order-1 one) and point sets.
//! Output: one SVG document, y axis pointing up, scaled to the union of the layers.

use crate::quality::lagrange_1d;
use crate::sample::HighOrderMesh;
use std::fmt::Write;

/// One thing to draw.
pub enum Layer<'a> {
    /// Element edges of a 2D mesh, in a colour, with a stroke width relative to the default.
    Mesh {
        mesh: &'a HighOrderMesh,
        colour: &'a str,
        width: f64,
        label: &'a str,
    },
    /// Points as small discs.
    Points {
        points: &'a [[f64; 3]],
        colour: &'a str,
        label: &'a str,
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

/// Render layers to an SVG document `size` pixels wide.
pub fn render_svg(layers: &[Layer], size: f64) -> String {
    let mut lo = [f64::INFINITY; 2];
    let mut hi = [f64::NEG_INFINITY; 2];
    let mut grow = |x: &[f64]| {
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
            } => {
                let _ = writeln!(svg, "<g fill=\"{colour}\"><title>{label}</title>");
                for x in points.iter() {
                    let (a, b) = tx(x);
                    let _ = writeln!(svg, "<circle cx=\"{a:.2}\" cy=\"{b:.2}\" r=\"2.4\"/>");
                }
                let _ = writeln!(svg, "</g>");
            }
        }
    }
    let _ = writeln!(svg, "</svg>");
    svg
}
