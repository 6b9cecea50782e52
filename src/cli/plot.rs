//! `polyspline plot`: a 2D mesh as SVG, curved edges as curves.

use super::{FeatureArgs, KnotArgs, read_high_order};
use polyspline::io::output::{check_outputs, write_atomically};
use polyspline::io::read_mesh;
use polyspline::mesh::{MeshOptions, Topology};
use polyspline::plot::{Layer, render_svg_window};
use polyspline::plot::{check_plot_labels, check_plot_width, parse_window};
use std::path::{Path, PathBuf};

#[derive(clap::Args)]
pub(super) struct Args {
    /// Mesh file (.msh, .vtu, or any input format).
    mesh: PathBuf,
    /// Output SVG file.
    #[arg(short, long)]
    output: PathBuf,
    /// Draw another mesh on top, in its own colour (e.g. the linear input, or a second
    /// method's result: IGA vs elastic as in the paper's Fig. 2f). Repeatable.
    #[arg(long, value_name = "MESH")]
    overlay: Vec<PathBuf>,
    /// Legend labels: the first for MESH, then one per --overlay (default: file names).
    #[arg(long, value_name = "NAME")]
    label: Vec<String>,
    /// Also draw every mesh's nodes (high-order nodes included) as dots in its colour.
    #[arg(long)]
    nodes: bool,
    /// Show only this rectangle of the plane (a zoom): X0,Y0,X1,Y1.
    #[arg(long, value_name = "X0,Y0,X1,Y1", allow_hyphen_values = true)]
    window: Option<String>,
    /// Picture width in pixels.
    #[arg(long, default_value_t = 1000.0)]
    width: f64,
    /// MESH is a linear input: also draw its poly-spline control points and the unfitted
    /// spline map they define (paper Fig. 1).
    #[arg(long)]
    control_points: bool,
    /// MESH is a linear input: also mark its sharp features (2D: corners of the boundary
    /// polygon), found with the --feature-* options.
    #[arg(long)]
    show_features: bool,
    #[command(flatten)]
    features: FeatureArgs,
    /// With --control-points: the knot intervals of the unfitted spline map.
    #[command(flatten)]
    knots: KnotArgs,
}

/// Colours of MESH and the overlays, in turn.
const COLOURS: [&str; 5] = ["#222222", "#1f77b4", "#9467bd", "#d62728", "#2ca02c"];

pub(super) fn run(args: Args) -> anyhow::Result<()> {
    let Args {
        mesh,
        output,
        overlay,
        label,
        nodes,
        window,
        width,
        control_points,
        show_features,
        features,
        knots,
    } = args;
    let inputs: Vec<&Path> = std::iter::once(mesh.as_path())
        .chain(overlay.iter().map(|p| p.as_path()))
        .collect();
    {
        let mut checked = inputs.clone();
        checked.extend(features.feature_edits.as_deref());
        check_outputs(&[&output], &checked)?;
    }
    check_plot_width(width)?;
    check_plot_labels(label.len(), overlay.len() + 1)?;
    let labels: Vec<String> = inputs
        .iter()
        .enumerate()
        .map(|(i, p)| {
            label.get(i).cloned().unwrap_or_else(|| {
                p.file_name()
                    .map_or(String::new(), |n| n.to_string_lossy().into_owned())
            })
        })
        .collect();
    let window = window.as_deref().map(parse_window).transpose()?;
    let base = read_high_order(&mesh)?;
    // The spline construction of a linear input (paper Fig. 1): its control points and the
    // unfitted spline map they define.
    let spline = if control_points {
        let linear = read_mesh(&mesh, &MeshOptions::default())?;
        let topo = Topology::build(&linear);
        let (space, _) =
            polyspline::spline::SplineSpace::build_for_knots(&linear, &topo, &knots.params())?;
        let curved = polyspline::sample::sample(&space, &linear, &topo, 4);
        Some((space.control_points, curved))
    } else {
        None
    };
    let others = overlay
        .iter()
        .map(|p| read_high_order(p))
        .collect::<Result<Vec<_>, _>>()?;
    for (m, p) in std::iter::once((&base, &mesh)).chain(others.iter().zip(&overlay)) {
        if m.dim != 2 {
            anyhow::bail!("{}: plot draws 2D meshes; this mesh is 3D", p.display());
        }
    }
    let mut layers = Vec::new();
    for (i, m) in std::iter::once(&base).chain(&others).enumerate() {
        let colour = COLOURS[i % COLOURS.len()];
        layers.push(Layer::Mesh {
            mesh: m,
            colour,
            width: 1.0,
            label: &labels[i],
        });
        if nodes {
            layers.push(Layer::Points {
                points: &m.nodes,
                colour,
                label: &labels[i],
                radius: 1.6,
            });
        }
    }
    // Feature corners of a linear input, drawn on top.
    let corners: Vec<[f64; 3]> = if show_features {
        let linear = read_mesh(&mesh, &MeshOptions::default())?;
        let topo = Topology::build(&linear);
        let found = features.options().detect(&linear, &topo)?;
        found
            .corners
            .iter()
            .map(|&v| linear.coords[v as usize])
            .collect()
    } else {
        Vec::new()
    };
    if show_features {
        layers.push(Layer::Points {
            points: &corners,
            colour: "#ff7f0e",
            label: "feature corners",
            radius: 4.0,
        });
    }
    if let Some((points, curved)) = &spline {
        layers.push(Layer::Mesh {
            mesh: curved,
            colour: "#1f77b4",
            width: 0.8,
            label: "unfitted spline map",
        });
        layers.push(Layer::Points {
            points,
            colour: "#d62728",
            label: "control points",
            radius: 2.4,
        });
    }
    let legend = !others.is_empty() || nodes || show_features;
    let svg = render_svg_window(&layers, width, window, legend);
    write_atomically(&output, &inputs, |w| {
        use std::io::Write;
        w.write_all(svg.as_bytes())
    })?;
    Ok(())
}
