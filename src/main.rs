//! The `polyspline` command line.

use clap::{Parser, Subcommand};
use polyspline::info::MeshInfo;
use polyspline::io::read_mesh;
use polyspline::mesh::{MeshOptions, Topology};
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
