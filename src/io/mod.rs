//! Mesh file input: one module per format, all producing a [`RawMesh`].
//!
//! [`read_mesh`] picks the reader from the file's extension (and, for `.mesh`, its first
//! line: Medit or MFEM), parses the whole file, and builds the [`LinearMesh`] with
//! [`LinearMesh::from_raw`]. Every failure is a [`ReadError`] whose message names the file, the
//! place (line or byte offset) and the problem; no reader panics on any input.
//!
//! | format | extensions | module |
//! |---|---|---|
//! | Gmsh MSH 2.0/2.2/4.1, ASCII and binary | `.msh` | [`gmsh`] |
//! | Medit | `.mesh`, `.meshb` is not supported | [`medit`] |
//! | MFEM mesh v1.0 | `.mesh` (first line `MFEM mesh v1.0`), `.mfem` | [`mfem`] |
//! | VTK legacy 3.0/4.2/5.1, ASCII and binary | `.vtk` | [`vtk`] |
//! | VTK XML unstructured grid | `.vtu` | [`vtu`] |
//! | SU2 | `.su2` | [`su2`] |
//! | Abaqus | `.inp` | [`abaqus`] |
//! | Exodus II (netCDF-3 classic / 64-bit offset) | `.exo`, `.e`, `.ex2`, `.exii`, `.g` (netCDF header), `.gen` | [`exodus`] |
//! | CGNS (HDF5 or ADF) | `.cgns`, `.hdf`, `.adf` | [`cgns`] |
//! | Plot3D grids, formatted or Fortran unformatted | `.x`, `.xyz`, `.p3d`, `.g` (no netCDF header) | [`plot3d`] |

pub mod abaqus;
pub mod abaqus_write;
pub mod cgns;
pub mod exodus;
mod from_raw;
pub mod glue;
pub mod gmsh;
pub mod gmsh_write;
pub mod high_order;
pub mod input;
pub mod medit;
pub mod mfem;
pub mod ordering;
pub mod output;
pub mod plot3d;
pub mod su2;
pub mod text;
pub mod vtk;
pub mod vtu;
pub mod vtu_write;

/// Helpers shared by the readers' unit tests.
#[cfg(test)]
pub(crate) mod test_util {
    use crate::mesh::raw::{CellKind, RawBlock, RawMesh};

    /// The bytes of the repository file `path` (relative to its root).
    pub fn real(path: &str) -> Vec<u8> {
        std::fs::read(format!("{}/{path}", env!("CARGO_MANIFEST_DIR"))).unwrap()
    }

    /// The number of cells of kind `k`.
    pub fn count(m: &RawMesh, k: &CellKind) -> usize {
        m.count(k)
    }

    /// The block of kind `k`, which must exist.
    pub fn block<'a>(m: &'a RawMesh, k: &CellKind) -> &'a RawBlock {
        m.block(k).unwrap()
    }
}

use crate::mesh::features::{FeatureEdit, FeatureError, parse_edits};
pub use crate::mesh::raw::{CellKind, Location, NodeConvention, ParseError, RawBlock, RawMesh};
use crate::mesh::{LinearMesh, MeshOptions};
use std::path::{Path, PathBuf};

/// A mesh file that could not be read or is not a mesh polyspline can curve.
#[derive(Debug, thiserror::Error)]
pub enum ReadError {
    #[error("{}: cannot read: {source}", path.display())]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error(
        "{}: unknown mesh format {what}; supported: .msh (Gmsh 2/4), .mesh (Medit or MFEM), .vtk, .vtu, .su2, .inp (Abaqus), .exo (Exodus II), .cgns (CGNS, HDF5 or ADF), .x/.xyz/.p3d/.g (Plot3D)",
        path.display()
    )]
    UnknownFormat { path: PathBuf, what: String },
    #[error("{}: {source}", path.display())]
    Parse {
        path: PathBuf,
        #[source]
        source: ParseError,
    },
}

impl ReadError {
    /// The place and problem without the path.
    pub fn parse_error(&self) -> Option<&ParseError> {
        match self {
            ReadError::Parse { source, .. } => Some(source),
            _ => None,
        }
    }
}

/// File formats polyspline reads.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Format {
    Gmsh,
    Medit,
    Mfem,
    Vtk,
    Vtu,
    Su2,
    Abaqus,
    Exodus,
    Cgns,
    Plot3d,
}

impl Format {
    /// Guess the format from the extension and the first bytes of the file.
    pub fn detect(path: &Path, head: &[u8]) -> Option<Format> {
        let ext = path
            .extension()
            .and_then(|e| e.to_str())
            .map(|e| e.to_ascii_lowercase())
            .unwrap_or_default();
        let starts = |s: &[u8]| {
            let trimmed = head
                .iter()
                .position(|b| !b.is_ascii_whitespace())
                .map_or(&head[..0], |p| &head[p..]);
            trimmed.len() >= s.len() && trimmed[..s.len()].eq_ignore_ascii_case(s)
        };
        match ext.as_str() {
            "msh" => Some(Format::Gmsh),
            "mesh" if starts(b"MFEM") => Some(Format::Mfem),
            "mesh" => Some(Format::Medit),
            "mfem" => Some(Format::Mfem),
            "vtk" => Some(Format::Vtk),
            "vtu" => Some(Format::Vtu),
            "su2" => Some(Format::Su2),
            "inp" => Some(Format::Abaqus),
            // `.g` is both Exodus's (a netCDF or HDF5 file) and Plot3D's.
            "g" if head.starts_with(b"CDF") || cgns::container(head).is_some() => {
                Some(Format::Exodus)
            }
            "g" | "x" | "xyz" | "p3d" => Some(Format::Plot3d),
            "exo" | "e" | "ex2" | "exii" | "gen" => Some(Format::Exodus),
            "cgns" | "hdf" | "adf" => Some(Format::Cgns),
            _ => {
                // Unknown extension: recognise a few self-describing headers.
                if starts(b"$MeshFormat") {
                    Some(Format::Gmsh)
                } else if starts(b"MFEM mesh") {
                    Some(Format::Mfem)
                } else if starts(b"# vtk DataFile") {
                    Some(Format::Vtk)
                } else if head.starts_with(b"CDF\x01") || head.starts_with(b"CDF\x02") {
                    Some(Format::Exodus)
                } else if cgns::container(head).is_some() {
                    Some(Format::Cgns)
                } else {
                    None
                }
            }
        }
    }

    /// Parse a whole file held in memory.
    pub fn parse(self, data: &[u8]) -> Result<RawMesh, ParseError> {
        match self {
            Format::Gmsh => gmsh::read(data),
            Format::Medit => medit::read(data),
            Format::Mfem => mfem::read(data),
            Format::Vtk => vtk::read(data),
            Format::Vtu => vtu::read(data),
            Format::Su2 => su2::read(data),
            Format::Abaqus => abaqus::read(data),
            Format::Exodus => exodus::read(data),
            Format::Cgns => cgns::read(data),
            Format::Plot3d => plot3d::read(data),
        }
    }
}

/// Read and parse a file into a [`RawMesh`] without building the linear mesh.
pub fn read_raw(path: &Path) -> Result<RawMesh, ReadError> {
    let data = input::read_regular(path).map_err(|source| ReadError::Io {
        path: path.to_owned(),
        source,
    })?;
    let format = Format::detect(path, &data[..data.len().min(64)]).ok_or_else(|| {
        ReadError::UnknownFormat {
            path: path.to_owned(),
            what: match path.extension() {
                Some(e) => format!("(extension .{})", e.to_string_lossy()),
                None => "(no extension, no known header)".into(),
            },
        }
    })?;
    format.parse(&data).map_err(|source| ReadError::Parse {
        path: path.to_owned(),
        source,
    })
}

/// Read a feature edits file (`--feature-edits`, [`parse_edits`]); the errors name the file.
pub fn read_feature_edits(path: &Path) -> Result<Vec<FeatureEdit>, FeatureError> {
    let text = input::read_regular_text(path).map_err(|source| FeatureError::Io {
        path: path.to_owned(),
        source,
    })?;
    parse_edits(&text, path)
}

/// Read a mesh file into a checked, orientation-normalised [`LinearMesh`].
pub fn read_mesh(path: &Path, options: &MeshOptions) -> Result<LinearMesh, ReadError> {
    let raw = read_raw(path)?;
    LinearMesh::from_raw(raw, options).map_err(|source| ReadError::Parse {
        path: path.to_owned(),
        source,
    })
}

#[cfg(test)]
mod tests {
    /// A missing edits file is an error naming the file.
    #[test]
    fn missing_feature_edits_file_is_named() {
        let missing = super::read_feature_edits("/nonexistent/edits.txt".as_ref()).unwrap_err();
        assert!(missing.to_string().starts_with("/nonexistent/edits.txt: "));
    }
}
