//! Output dispatch of high-order meshes: the format from the file extension ([`OutputFormat`]),
//! its options ([`OutputOptions`]), and the atomic write of the mesh and its optional boundary
//! file ([`write_high_order`], [`prepare_high_order`]).
//!
//! Input: a [`HighOrderMesh`] and a path. Output: the file in the format its extension names
//! (`.msh`: [`crate::io::gmsh_write`], `.vtu`: [`crate::io::vtu_write`], `.cgns`:
//! [`crate::io::cgns::write`]), written through a
//! synced temporary and renamed into place ([`crate::io::output`]); never onto an input.

use crate::io::gmsh_write::{DEFAULT_VOLUME_NAME, MshVersion, write_msh_named};
use crate::io::output::{PendingFile, WriteError, write_atomically};
use crate::io::vtu_write::{VtuCells, VtuEncoding, write_vtu_cells};
use crate::mesh::HighOrderMesh;
use crate::params::ParamError;
use std::path::{Path, PathBuf};

/// Output file options.
#[derive(Clone, Debug)]
pub struct OutputOptions {
    pub msh_version: MshVersion,
    pub binary: bool,
    pub vtu_encoding: VtuEncoding,
    /// Name of the MSH volume group where the input names no region (`fluid`, as PyFR needs).
    pub volume_name: String,
    /// Also write the boundary facets to this VTU file (the main VTU holds the volume only).
    pub vtu_boundary: Option<PathBuf>,
}

impl Default for OutputOptions {
    fn default() -> Self {
        OutputOptions {
            msh_version: MshVersion::V41,
            binary: false,
            vtu_encoding: VtuEncoding::Base64,
            volume_name: DEFAULT_VOLUME_NAME.into(),
            vtu_boundary: None,
        }
    }
}

impl OutputOptions {
    /// `--volume-name`: non-empty, without quotes or line breaks (it is written into the file).
    pub fn check(&self) -> Result<(), ParamError> {
        let name = &self.volume_name;
        if name.is_empty() || name.contains(['"', '\n', '\r']) {
            return Err(ParamError::new(
                "--volume-name",
                format!("{name:?}"),
                "must be non-empty, without quotes or line breaks",
            ));
        }
        Ok(())
    }
}

/// The message for an output path of no known format.
pub const UNKNOWN_OUTPUT: &str = "unknown output format; use .msh (Gmsh), .vtu (VTK), .cgns (CGNS/HDF5) or .inp (Abaqus for Trixi.jl)";

/// Output format from the file extension.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum OutputFormat {
    Msh,
    Vtu,
    Cgns,
    /// Abaqus for Trixi.jl (order 2).
    Inp,
}

impl OutputFormat {
    /// The format of `path`, or the error naming the formats there are.
    pub fn require(path: &Path) -> Result<OutputFormat, WriteError> {
        OutputFormat::from_path(path).ok_or_else(|| WriteError::Unsupported {
            path: path.to_owned(),
            what: UNKNOWN_OUTPUT.into(),
        })
    }

    /// Why a mesh of dimension `dim` and order `order` cannot be written in this format, as
    /// one line (checked before any work and again on the mesh).
    pub fn refuses(self, dim: usize, order: usize) -> Option<String> {
        let mesh = HighOrderMesh {
            dim,
            order,
            ..Default::default()
        };
        self.unsupported(&mesh)
    }

    fn unsupported(self, mesh: &HighOrderMesh) -> Option<String> {
        match self {
            OutputFormat::Msh if mesh.dim == 3 && mesh.order > 9 => Some(format!(
                "Gmsh has no hexahedron of order {}; the highest is 9 (use .vtu for order 10)",
                mesh.order
            )),
            OutputFormat::Cgns => crate::io::cgns::write::unsupported(mesh),
            OutputFormat::Inp => crate::io::abaqus_write::unsupported(mesh),
            _ => None,
        }
    }

    pub fn from_path(path: &Path) -> Option<OutputFormat> {
        match path.extension()?.to_str()?.to_ascii_lowercase().as_str() {
            "msh" => Some(OutputFormat::Msh),
            "vtu" => Some(OutputFormat::Vtu),
            "cgns" => Some(OutputFormat::Cgns),
            "inp" => Some(OutputFormat::Inp),
            _ => None,
        }
    }
}

/// Write a high-order mesh to `path` in the format its extension names, and its boundary
/// facets to `options.vtu_boundary` when that is set.
pub fn write_high_order(
    mesh: &HighOrderMesh,
    path: &Path,
    options: &OutputOptions,
    inputs: &[&Path],
) -> Result<(), WriteError> {
    prepare_high_order(mesh, path, options, inputs)?.commit()
}

/// [`write_high_order`] into a synced temporary beside `path`, renamed into place by
/// [`crate::io::output::PendingFile::commit`] (so several outputs can all be written before
/// any replaces its target).
pub fn prepare_high_order(
    mesh: &HighOrderMesh,
    path: &Path,
    options: &OutputOptions,
    inputs: &[&Path],
) -> Result<PendingFile, WriteError> {
    let format = OutputFormat::require(path)?;
    if let Some(what) = format.unsupported(mesh) {
        return Err(WriteError::Unsupported {
            path: path.to_owned(),
            what,
        });
    }
    if let Some(bpath) = &options.vtu_boundary {
        if OutputFormat::from_path(bpath) != Some(OutputFormat::Vtu) {
            return Err(WriteError::Unsupported {
                path: bpath.clone(),
                what: "the boundary file is written as VTU; give it the extension .vtu".into(),
            });
        }
        if bpath == path {
            return Err(WriteError::Unsupported {
                path: bpath.clone(),
                what: "the boundary file would overwrite the mesh output; choose another path"
                    .into(),
            });
        }
        // The secondary boundary file is written (atomically) before the mesh is prepared.
        let mut not_onto: Vec<&Path> = inputs.to_vec();
        not_onto.push(path);
        write_atomically(bpath, &not_onto, |w| {
            write_vtu_cells(mesh, options.vtu_encoding, VtuCells::Boundary, w)
        })?;
    }
    crate::io::output::prepare(path, inputs, |w| match format {
        OutputFormat::Msh => write_msh_named(
            mesh,
            options.msh_version,
            options.binary,
            &options.volume_name,
            w,
        ),
        OutputFormat::Vtu => write_vtu_cells(mesh, options.vtu_encoding, VtuCells::Volume, w),
        OutputFormat::Cgns => crate::io::cgns::write::write_cgns(mesh, &options.volume_name, w),
        OutputFormat::Inp => crate::io::abaqus_write::write_abaqus(mesh, &options.volume_name, w),
    })
}
