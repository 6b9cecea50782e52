//! The `polyspline` command line.

use clap::{Parser, Subcommand};
use polyspline::info::MeshInfo;
use polyspline::io::gmsh_write::MshVersion;
use polyspline::io::output::write_atomically;
use polyspline::io::read_mesh;
use polyspline::io::vtu_write::VtuEncoding;
use polyspline::mesh::{MeshOptions, Topology};
use polyspline::pipeline::{CurveOptions, Geometry, OutputOptions, curve};
use std::path::PathBuf;
use std::process::ExitCode;

#[derive(Parser)]
#[command(
    name = "polyspline",
    version,
    about = "Curved high-order quad/hex meshes from linear ones, without CAD"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Read a linear quad/hex mesh and report its size, topology and quality.
    Info {
        /// Mesh file (.msh, .mesh, .vtk, .vtu, .su2, .inp, .exo).
        mesh: PathBuf,
        /// Print one JSON object instead of a table.
        #[arg(long)]
        json: bool,
        /// Keep tangled or degenerate elements instead of failing.
        #[arg(long)]
        allow_invalid: bool,
    },
    /// Make a curved high-order mesh from a linear quad/hex mesh.
    Curve {
        /// Input mesh file.
        mesh: PathBuf,
        /// Output file: .msh (Gmsh) or .vtu (VTK Lagrange cells).
        #[arg(short, long)]
        output: PathBuf,
        /// Order of the output elements (1-10; Gmsh hexes up to 9).
        #[arg(long, default_value_t = 2)]
        order: usize,
        /// Write the straight-sided order-P mesh of the input (no curving), for comparison.
        #[arg(long)]
        straight: bool,
        /// With --order 1: split each element into K^d linear elements on the curved geometry.
        #[arg(long, value_name = "K")]
        subdivide: Option<usize>,
        /// Gmsh file version.
        #[arg(long, value_enum, default_value_t = MshVersionArg::V41)]
        msh_version: MshVersionArg,
        /// Binary Gmsh output.
        #[arg(long)]
        binary: bool,
        /// How VTU data arrays are stored.
        #[arg(long, value_enum, default_value_t = VtuEncodingArg::Base64)]
        vtu_encoding: VtuEncodingArg,
        /// Write a JSON report (sizes, timings) to this file.
        #[arg(long, value_name = "FILE.json")]
        report: Option<PathBuf>,
        /// Keep tangled or degenerate input elements instead of failing.
        #[arg(long)]
        allow_invalid: bool,
    },
}

#[derive(Clone, Copy, clap::ValueEnum)]
enum MshVersionArg {
    #[value(name = "4.1")]
    V41,
    #[value(name = "2.2")]
    V22,
}

#[derive(Clone, Copy, clap::ValueEnum)]
enum VtuEncodingArg {
    Ascii,
    Base64,
    Appended,
}

fn run(cli: Cli) -> anyhow::Result<()> {
    match cli.command {
        Command::Info {
            mesh,
            json,
            allow_invalid,
        } => {
            let options = MeshOptions { allow_invalid };
            let linear = read_mesh(&mesh, &options)?;
            let topo = Topology::build(&linear);
            let info = MeshInfo::new(&linear, &topo);
            if json {
                println!("{}", serde_json::to_string_pretty(&info)?);
            } else {
                println!("{:<22}{}", "mesh", mesh.display());
                print!("{info}");
            }
        }
        Command::Curve {
            mesh,
            output,
            order,
            straight,
            subdivide,
            msh_version,
            binary,
            vtu_encoding,
            report,
            allow_invalid,
        } => {
            if !straight {
                anyhow::bail!(
                    "only --straight is available in this version: the spline geometry is not built yet"
                );
            }
            let options = CurveOptions {
                order,
                subdivide,
                geometry: Geometry::Straight,
                mesh: MeshOptions { allow_invalid },
                output: OutputOptions {
                    msh_version: match msh_version {
                        MshVersionArg::V41 => MshVersion::V41,
                        MshVersionArg::V22 => MshVersion::V22,
                    },
                    binary,
                    vtu_encoding: match vtu_encoding {
                        VtuEncodingArg::Ascii => VtuEncoding::Ascii,
                        VtuEncodingArg::Base64 => VtuEncoding::Base64,
                        VtuEncodingArg::Appended => VtuEncoding::Appended,
                    },
                },
            };
            let r = curve(&mesh, &output, &options)?;
            eprintln!(
                "wrote {}: {} elements of order {}, {} nodes, {} boundary facets ({:.3} s)",
                r.output.display(),
                r.output_elements,
                r.order,
                r.output_nodes,
                r.boundary_facets,
                r.timings["total"]
            );
            if let Some(path) = report {
                let json = serde_json::to_string_pretty(&r)?;
                write_atomically(&path, &[&mesh], |w| {
                    use std::io::Write;
                    writeln!(w, "{json}")
                })?;
            }
        }
    }
    Ok(())
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    match run(cli) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("polyspline: error: {e}");
            ExitCode::FAILURE
        }
    }
}
