//! `polyspline generate`: synthetic linear meshes with curved boundaries.

use super::values;
use polyspline::io::output::check_outputs;
use polyspline::mesh::generate::boundary_layer::{self, BoundaryLayer, Wall};
use polyspline::mesh::generate::{Shape, generate};
use polyspline::mesh::{HighOrderMesh, Topology, periodic};
use polyspline::pipeline::{OutputOptions, write_high_order};
use std::path::{Path, PathBuf};

#[derive(clap::Args)]
pub(super) struct Args {
    #[command(flatten)]
    shape: ShapeArgs,
    /// Output file (.msh or .vtu).
    #[arg(short, long)]
    output: PathBuf,
    /// Binary Gmsh output.
    #[arg(long)]
    binary: bool,
}

/// The mesh to make (shared with the Python package's `generate`, which writes through the
/// output options of `curve`).
#[derive(clap::Args)]
pub(crate) struct ShapeArgs {
    #[arg(value_enum)]
    kind: values::GenerateShape,
    /// Approximate number of elements (disc, cylinder, torus).
    #[arg(long, required_if_eq_any([("kind", "disc"), ("kind", "cylinder"), ("kind", "torus")]))]
    elements: Option<usize>,
    #[command(flatten)]
    layer: BoundaryLayerArgs,
}

/// A generated mesh: its order-1 high-order form (what `generate` writes), the counts it
/// reports, and the boundary layer's spacing line (O- and C-grids).
pub(crate) struct Generated {
    pub(crate) mesh: HighOrderMesh,
    pub(crate) elements: usize,
    pub(crate) vertices: usize,
    pub(crate) boundary_facets: usize,
    pub(crate) spacing: Option<String>,
}

/// Options of `generate ogrid|cgrid|channel|sector` (lengths in wall units: chord 2 for the
/// ellipse and the circle, 1 for the airfoil; the channel's period and height are 1, the
/// sector's hub and shroud radii 1 and 2). The channel and the sector take `--around` along
/// the period, `--across` wall to wall.
#[derive(clap::Args)]
pub(crate) struct BoundaryLayerArgs {
    /// Wall curve [default: ellipse for ogrid, naca for cgrid].
    #[arg(long, value_enum)]
    wall: Option<values::WallShape>,
    /// Ellipse: minor/major semi-axis ratio (default 0.2); airfoil: maximum thickness over
    /// chord (default 0.12).
    #[arg(long)]
    thickness: Option<f64>,
    /// Cells around the wall (even for the airfoil) [default: 128].
    #[arg(long)]
    around: Option<usize>,
    /// Cells from the wall to the far field [default: 48].
    #[arg(long)]
    across: Option<usize>,
    /// Height of the first cell off the wall (absolute) [default: 1e-5].
    #[arg(long)]
    first_height: Option<f64>,
    /// Wall-normal growth ratio of the cell heights near the wall [default: 1.25].
    #[arg(long)]
    growth: Option<f64>,
    /// Far-field radius in chords (ogrid, cgrid) [default: 10].
    #[arg(long)]
    farfield: Option<f64>,
    /// 0: 2D quads; L >= 1: L hex layers extruded along z over --span [default: 0].
    #[arg(long)]
    layers: Option<usize>,
    /// Extrusion length along z [default: 1].
    #[arg(long)]
    span: Option<f64>,
    /// C-grid: cells along the wake cut [default: 32].
    #[arg(long)]
    wake: Option<usize>,
    /// Channel: bump height (the period and the channel height are 1) [default: 0.1].
    #[arg(long)]
    bump: Option<f64>,
    /// Sector: angle in degrees [default: 30].
    #[arg(long)]
    sector: Option<f64>,
}

impl BoundaryLayerArgs {
    fn params(&self, cgrid: bool) -> BoundaryLayer {
        let default = if cgrid {
            Wall::NACA_0012
        } else {
            Wall::ELLIPSE
        };
        BoundaryLayer {
            wall: self
                .wall
                .map_or(default, Wall::from)
                .with_thickness(self.thickness),
            around: self.around.unwrap_or(128),
            across: self.across.unwrap_or(48),
            first_height: self.first_height.unwrap_or(1e-5),
            growth: self.growth.unwrap_or(1.25),
            farfield: self.farfield.unwrap_or(10.0),
            layers: self.layers.unwrap_or(0),
            span: self.span.unwrap_or(1.0),
            wake: self.wake.unwrap_or(32),
        }
    }

    /// The options given on the command line that `shape` does not use: refused, never
    /// silently ignored.
    fn check_applies(&self, shape: Shape, kind: &str) -> anyhow::Result<()> {
        let given = [
            ("--wall", self.wall.is_some()),
            ("--thickness", self.thickness.is_some()),
            ("--around", self.around.is_some()),
            ("--across", self.across.is_some()),
            ("--first-height", self.first_height.is_some()),
            ("--growth", self.growth.is_some()),
            ("--farfield", self.farfield.is_some()),
            ("--layers", self.layers.is_some()),
            ("--span", self.span.is_some()),
            ("--wake", self.wake.is_some()),
            ("--bump", self.bump.is_some()),
            ("--sector", self.sector.is_some()),
        ];
        let layer = [
            "--around",
            "--across",
            "--first-height",
            "--growth",
            "--layers",
            "--span",
        ];
        let applies = |name: &str| match shape {
            Shape::Benchmark(_) => false,
            Shape::Ogrid => {
                layer.contains(&name) || ["--wall", "--thickness", "--farfield"].contains(&name)
            }
            Shape::Cgrid => {
                layer.contains(&name)
                    || ["--wall", "--thickness", "--farfield", "--wake"].contains(&name)
            }
            Shape::Channel => layer.contains(&name) || name == "--bump",
            Shape::Sector => layer.contains(&name) || name == "--sector",
        };
        match given.iter().find(|(name, set)| *set && !applies(name)) {
            Some((name, _)) => anyhow::bail!("generate {kind}: {name} does not apply to {kind}"),
            None => Ok(()),
        }
    }
}

/// Make the mesh `args` describes; `name` prefixes the generator's errors (the output path).
pub(crate) fn make(args: &ShapeArgs, name: &Path) -> anyhow::Result<Generated> {
    let shape = Shape::from(args.kind);
    shape.check(args.elements)?;
    let kind = clap::ValueEnum::to_possible_value(&args.kind)
        .map_or_else(String::new, |v| v.get_name().to_owned());
    args.layer.check_applies(shape, &kind)?;
    let mut spacing = None;
    let mesh = match shape {
        Shape::Benchmark(kind) => generate(kind, args.elements.unwrap_or_default()),
        Shape::Ogrid | Shape::Cgrid | Shape::Channel | Shape::Sector => {
            let cgrid = shape == Shape::Cgrid;
            let params = args.layer.params(cgrid);
            let made = match shape {
                Shape::Cgrid => boundary_layer::cgrid(&params),
                Shape::Channel => boundary_layer::channel(&params, args.layer.bump.unwrap_or(0.1)),
                Shape::Sector => boundary_layer::sector(&params, args.layer.sector.unwrap_or(30.0)),
                _ => boundary_layer::ogrid(&params),
            }
            .map_err(|e| anyhow::anyhow!("{}: {e}", name.display()))?;
            let s = &made.spacing;
            spacing = Some(format!(
                "wall-normal: {} cells from {:e} growing by {}, then {} cells by {:.4} to the far field; min scaled Jacobian {:.4}, max aspect ratio {:.4e}",
                s.geometric_cells,
                params.first_height,
                params.growth,
                s.distances.len() - 1 - s.geometric_cells,
                s.outer_growth,
                made.mesh.min_scaled_jacobian().map_or(0.0, |m| m.0),
                boundary_layer::max_aspect_ratio(&made.mesh),
            ));
            made.mesh
        }
    };
    let topo = Topology::build(&mesh);
    let mut ho = polyspline::sample::sample(&mesh, &mesh, &topo, 1);
    // The periodic shapes carry their pair (written as `$Periodic`), verified like --periodic.
    let pair = match shape {
        Shape::Channel => Some(boundary_layer::CHANNEL_PAIR),
        Shape::Sector => Some(boundary_layer::SECTOR_PAIR),
        _ => None,
    };
    if let Some(pair) = pair {
        let spec = pair.parse().map_err(anyhow::Error::msg)?;
        let fail = |e: periodic::PeriodicError| anyhow::anyhow!("{}: {e}", name.display());
        let pairs = periodic::resolve(&mesh, &topo, &[spec]).map_err(fail)?;
        ho.periodic = periodic::node_pairs(&ho, &pairs).map_err(fail)?;
    }
    Ok(Generated {
        mesh: ho,
        elements: mesh.n_elements(),
        vertices: mesh.n_vertices(),
        boundary_facets: topo.boundary_facets.len(),
        spacing,
    })
}

pub(super) fn run(args: Args) -> anyhow::Result<()> {
    let output = &args.output;
    Shape::from(args.shape.kind).check(args.shape.elements)?;
    check_outputs(&[output], &[])?;
    // Binary is a Gmsh MSH option: refused for another format, not ignored.
    let format = polyspline::pipeline::OutputFormat::from_path(output);
    if args.binary && format.is_some_and(|f| f != polyspline::pipeline::OutputFormat::Msh) {
        anyhow::bail!(
            "{}: --binary does not apply (it sets the Gmsh MSH writer and the output is not .msh); drop it",
            output.display()
        );
    }
    let made = make(&args.shape, output)?;
    if let Some(line) = &made.spacing {
        eprintln!("{line}");
    }
    let options = OutputOptions {
        binary: args.binary,
        ..Default::default()
    };
    write_high_order(&made.mesh, output, &options, &[])?;
    eprintln!(
        "wrote {}: {} elements, {} vertices, {} boundary facets",
        output.display(),
        made.elements,
        made.vertices,
        made.boundary_facets
    );
    Ok(())
}
